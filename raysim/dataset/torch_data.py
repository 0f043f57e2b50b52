"""A PyTorch ``Dataset`` over a dataset store (needs ``torch``: ``pip install raysim[torch]``).

:class:`TorchDataset` wraps a :class:`raysim.dataset.loader.Loader`: item k is the
(input, target) pair of the k-th sample of the chosen split, as ``torch.Tensor``s (the
loader's normalisation, representation and NaN fill), so ``torch.utils.data.DataLoader``
batches and shuffles it. The statistics are computed (or read from the store) once, when
the dataset is made, before any worker process forks.
"""

from __future__ import annotations

from typing import Any

from raysim.dataset.loader import Loader

try:
    import torch
    from torch.utils.data import Dataset
except ImportError as exc:  # pragma: no cover - exercised only without torch
    raise ImportError("raysim.dataset.torch_data needs PyTorch: pip install 'raysim[torch]'") from exc


class TorchDataset(Dataset):
    """The samples of one split of a store as tensors; ``loader_options`` go to
    :class:`~raysim.dataset.loader.Loader` (``representation``, ``source``, ``split``, ...)."""

    def __init__(self, store: str, **loader_options: Any) -> None:
        self.loader = Loader(store, **loader_options)
        if self.loader.normalise:
            _ = self.loader.statistics

    def __len__(self) -> int:
        return len(self.loader.indices)

    def __getitem__(self, position: int) -> tuple[torch.Tensor, torch.Tensor]:
        x, y = self.loader.sample(int(position))
        return torch.from_numpy(x), torch.from_numpy(y)

    @property
    def target_mask(self) -> torch.Tensor:
        """True at the aperture points of the target grid."""
        return torch.from_numpy(self.loader.target_mask)
