"""Batches of a dataset store as JAX arrays (needs ``jax``: ``pip install raysim[jax]``).

:func:`jax_batches` runs one :class:`raysim.dataset.loader.Loader` epoch and hands each batch
to the device as ``jax.Array``s; a background thread reads the next batch from the store
while the consumer works on the current one.
"""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from raysim.dataset.loader import Loader

try:
    import jax
except ImportError as exc:  # pragma: no cover - exercised only without jax
    raise ImportError("raysim.dataset.jax_data needs JAX: pip install 'raysim[jax]'") from exc

_END = object()


def jax_batches(loader: Loader, device: Any = None) -> Iterator[tuple[jax.Array, jax.Array]]:
    """One epoch of ``loader`` as (input, target) JAX arrays on ``device`` (default: JAX's)."""
    batches = iter(loader)
    with ThreadPoolExecutor(max_workers=1) as pool:
        pending = pool.submit(next, batches, _END)
        while (batch := pending.result()) is not _END:
            pending = pool.submit(next, batches, _END)
            x, y = batch
            yield jax.device_put(x, device), jax.device_put(y, device)
