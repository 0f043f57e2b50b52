"""The quadtree of the fast radiator: elements sorted so that every cluster is a contiguous range.

Cells split the elements' bounding square in (x, y) (reflector frame; a dish seen along its
axis); level l has 2^l x 2^l cells, level 0 is the root. Elements are sorted by the Morton key
of their leaf cell, so a cluster at any level is a contiguous range of the sorted elements and
its parent's key is its own shifted right by two bits.
"""

from __future__ import annotations

import ctypes
import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: elements per step where (n,) temporaries are made a chunk at a time (8 MB each)
KEY_CHUNK = 1 << 20
#: freed pieces' bytes after which the allocator is asked to hand them back
TRIM_BYTES = 1 << 28


@dataclass(frozen=True)
class Level:
    """The non-empty clusters of one level: ``keys`` (C,) Morton keys (ascending), element
    ranges ``begins``/``ends`` (C,) into the sorted elements, ``centres`` (C, 3) m (bounding
    box middles) and ``radii`` (C,) m (largest element distance from the centre), and
    ``parent`` (C,): the index of each cluster's parent in the level above (-1 at the root)."""

    keys: NDArray[np.int64]
    begins: NDArray[np.int64]
    ends: NDArray[np.int64]
    centres: NDArray[np.float64]
    radii: NDArray[np.float64]
    parent: NDArray[np.int64]


def _morton(ix: NDArray[np.int64], iy: NDArray[np.int64], depth: int) -> NDArray[np.int64]:
    key = np.zeros_like(ix)
    for b in range(depth):
        key |= ((ix >> b) & 1) << (2 * b) | ((iy >> b) & 1) << (2 * b + 1)
    return key


def centre_distances(coords: NDArray[np.float64], begins: NDArray[np.int64],
                     centres: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each element's distance (m) from its cluster's centre: ``coords`` (3, n) the elements'
    x, y, z in leaf order, ``begins`` (C,) the first element of each cluster (ascending, the
    first 0) and ``centres`` (C, 3) m."""
    # a chunk of elements at a time: the only (n,) array is the result (at 12 GHz on the
    # paper's dish an (n,) float64 array is 0.9 GB)
    n = coords.shape[1]
    out = np.empty(n)
    for at in range(0, n, KEY_CHUNK):
        end = min(at + KEY_CHUNK, n)
        owner = np.searchsorted(begins, np.arange(at, end), side="right") - 1
        square = np.zeros(end - at)
        for axis in range(3):
            d = coords[axis, at:end] - centres[owner, axis]
            d *= d
            square += d
        np.sqrt(square, out=out[at:end])
    return out


def gathered(pieces: Sequence[NDArray[np.float64]], order: NDArray[np.int64], rows: int | None = None,
             consume: bool = False) -> NDArray[np.float64]:
    """The first ``rows`` rows (all by default) of ``pieces`` ((rows_i, n_i) each, consecutive
    elements) as one (rows, n) array whose column j is element ``order[j]`` of the pieces taken
    end to end, made a row at a time: besides the pieces and the result it holds one (n,) row.

    With ``consume`` (``pieces`` a list) the list is emptied as it is read and the pieces are
    freed as they go, where nothing else holds them, so the elements are held about once, not
    twice. The pieces are first copied into rows, the last piece first (so that the allocator
    can return their memory as they are freed: they were made in the list's order), then each
    row is gathered into the result and freed. (Filling the result from one piece at a time
    would touch its pages everywhere from the first piece on: a piece's elements are spread
    over the whole order.)"""
    n = sum(piece.shape[1] for piece in pieces)
    if len(order) != n:
        raise ValueError(f"an order of {len(order)} elements for {n}")
    if consume and not isinstance(pieces, list):
        raise TypeError("consume needs the pieces as a list")
    count = pieces[0].shape[0] if rows is None else rows
    out = np.empty((count, n))
    if not consume:
        for row in range(count):
            np.take(np.concatenate([piece[row] for piece in pieces]), order, out=out[row])
        return out
    assert isinstance(pieces, list)
    staged = [np.empty(n) for _ in range(count)]  # pages taken as they are written
    end = freed = n
    while pieces:
        piece = pieces.pop()
        for row in range(count):
            staged[row][end - piece.shape[1]:end] = piece[row]
        end -= piece.shape[1]
        del piece
        if (freed - end) * count * 8 >= TRIM_BYTES:
            freed = end
            _release_freed_memory()
    _release_freed_memory()
    for row in range(count):
        np.take(staged[row], order, out=out[row])
        staged[row] = np.empty(0)  # freed
    return out


def _release_freed_memory() -> None:
    """Hand the memory of freed arrays back to the system where the C library keeps it for
    reuse (glibc's ``malloc_trim``; nothing elsewhere). Pieces made after the allocator has
    raised its mmap threshold (it does, up to 32 MB, as large blocks are freed) live in its
    heap, and their pages stay resident after they are freed until it is trimmed."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


@functools.cache
def _malloc_trim() -> Any:
    try:
        return ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return None


def leaf_keys(pieces: Sequence[NDArray[np.float64]], depth: int) -> NDArray[np.int64]:
    """The Morton key of each element's leaf cell (2^depth x 2^depth cells over the elements'
    bounding square in x, y), ``pieces`` as :func:`build`'s, in their order."""
    lo = np.min([piece[:2].min(axis=1) for piece in pieces], axis=0)
    hi = np.max([piece[:2].max(axis=1) for piece in pieces], axis=0)
    side = float(np.max(hi - lo)) or 1.0
    cells = 1 << depth
    key = np.empty(sum(piece.shape[1] for piece in pieces), dtype=np.int64)
    at = 0
    for piece in pieces:
        for a in range(0, piece.shape[1], KEY_CHUNK):  # cell indices a chunk at a time
            ix, iy = (np.clip(((piece[axis, a:a + KEY_CHUNK] - lo[axis]) / side * cells).astype(np.int64),
                              0, cells - 1) for axis in (0, 1))
            key[at + a:at + a + len(ix)] = _morton(ix, iy, depth)
        at += piece.shape[1]
    return key


def build(pieces: Sequence[NDArray[np.float64]], depth: int) -> tuple[NDArray[np.int64], list[Level]]:
    """(order, levels): ``order`` sorts the elements into leaf order; ``levels[l]`` holds level
    l's clusters, l = 0 (root) .. depth (leaves). ``pieces``: (rows, n_i) arrays of
    consecutive elements whose first three rows are x, y, z (m; a kind's packed elements as
    they were added, or ``positions.T``). Besides the pieces it holds about 40 bytes an element
    at once (the order, the leaf-ordered coordinates and one more (n,) array), never an (n, 3)
    copy of the positions."""
    leaf_key = leaf_keys(pieces, depth)
    order = np.argsort(leaf_key, kind="stable")
    leaf_key = leaf_key[order]
    # every level's clusters start where a leaf cluster starts: the levels are read from the
    # leaf clusters' keys, and no (n,) key array outlives this line
    leaf_starts = np.flatnonzero(np.r_[True, leaf_key[1:] != leaf_key[:-1]])
    leaf_key = leaf_key[leaf_starts]
    coords = gathered(pieces, order, rows=3)
    n = len(order)
    levels: list[Level] = []
    for level in range(depth + 1):
        key = leaf_key >> (2 * (depth - level))
        first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        starts = leaf_starts[first]
        centres = np.empty((len(starts), 3))
        for axis in range(3):
            centres[:, axis] = 0.5 * (np.minimum.reduceat(coords[axis], starts)
                                      + np.maximum.reduceat(coords[axis], starts))
        radii = np.maximum.reduceat(centre_distances(coords, starts, centres), starts)
        levels.append(Level(key[first], starts, np.r_[starts[1:], n], centres, radii,
                            np.full(len(starts), -1)))
    for level in range(1, depth + 1):
        child, up = levels[level], levels[level - 1]
        parent = np.searchsorted(up.keys, child.keys >> 2)
        levels[level] = Level(child.keys, child.begins, child.ends, child.centres, child.radii, parent)
    return order, levels
