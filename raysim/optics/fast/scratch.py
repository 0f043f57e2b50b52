"""Reused buffers for the multilevel sum's walk (:mod:`raysim.optics.fast.multilevel`).

The walk makes the same few large temporaries over and over: a chunk of leaf grids, the
refined grids of a chunk of children, one chunk of each level's grids. Each is tens to hundreds
of megabytes, so a fresh one comes from a fresh mapping of memory, and the pages are faulted in
(zeroed by the system) on every use; on a virtual machine whose host backs the guest's pages
lazily a first touch can cost ten times the work done in it. A :class:`Scratch` keeps one
buffer per role and hands out views of it, so the pages are faulted once per walk.
"""

from __future__ import annotations

import math
from collections.abc import Hashable

import numpy as np
from numpy.typing import DTypeLike, NDArray


class Scratch:
    """Buffers by role: :meth:`array` returns an uninitialised array of the shape asked for,
    a view of the role's buffer (grown when too small). A role's previous array is overwritten
    by the next one, so a caller asks for a role only once the last array it had from it is no
    longer read. Not shared between threads: each walk makes its own."""

    def __init__(self) -> None:
        self._buffers: dict[Hashable, NDArray[np.uint8]] = {}

    def array(self, role: Hashable, shape: tuple[int, ...], dtype: DTypeLike = np.complex128) -> NDArray:
        dt = np.dtype(dtype)
        size = math.prod(shape) * dt.itemsize
        buffer = self._buffers.get(role)
        if buffer is None or buffer.nbytes < size:
            self._buffers.pop(role, None)  # let the old one go before the larger one is made
            buffer = self._buffers[role] = np.empty(max(size, 1), dtype=np.uint8)
        return buffer[:size].view(dt).reshape(shape)
