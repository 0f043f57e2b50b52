"""The quadtree of the fast radiator: elements sorted so that every cluster is a contiguous range.

Cells split the elements' bounding square in (x, y) (reflector frame; a dish seen along its
axis); level l has 2^l x 2^l cells, level 0 is the root. Elements are sorted by the Morton key
of their leaf cell, so a cluster at any level is a contiguous range of the sorted elements and
its parent's key is its own shifted right by two bits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


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


def centre_distances(pos: NDArray[np.float64], begins: NDArray[np.int64], ends: NDArray[np.int64],
                     centres: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each element's distance (m) from its cluster's centre: ``pos`` (n, 3) in leaf order,
    the clusters' element ranges ``begins``/``ends`` and ``centres`` (C, 3)."""
    # one coordinate at a time: two (n,) temporaries rather than several (n, 3) ones (at 6 GHz
    # on the paper's dish an (n, 3) array is 0.7 GB)
    counts = ends - begins
    square = np.zeros(len(pos))
    for axis in range(3):
        d = pos[:, axis] - np.repeat(centres[:, axis], counts)
        d *= d
        square += d
    return np.sqrt(square, out=square)


def build(positions: NDArray[np.float64], depth: int) -> tuple[NDArray[np.int64], list[Level]]:
    """(order, levels): ``order`` sorts the elements (n, 3 positions, m) into leaf order;
    ``levels[l]`` holds level l's clusters, l = 0 (root) .. depth (leaves)."""
    xy = positions[:, :2]
    lo = xy.min(axis=0)
    side = float(np.max(xy.max(axis=0) - lo)) or 1.0
    cells = 1 << depth
    ix, iy = (np.clip(((xy[:, a] - lo[a]) / side * cells).astype(np.int64), 0, cells - 1) for a in (0, 1))
    leaf_key = _morton(ix, iy, depth)
    del ix, iy
    order = np.argsort(leaf_key, kind="stable")
    sorted_key = leaf_key[order]
    del leaf_key
    pos = positions[order]
    levels: list[Level] = []
    for level in range(depth + 1):
        key = sorted_key >> (2 * (depth - level))
        starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        ends = np.r_[starts[1:], len(key)]
        lo3 = np.minimum.reduceat(pos, starts, axis=0)
        hi3 = np.maximum.reduceat(pos, starts, axis=0)
        centres = 0.5 * (lo3 + hi3)
        radii = np.maximum.reduceat(centre_distances(pos, starts, ends, centres), starts)
        levels.append(Level(key[starts], starts, ends, centres, radii, np.full(len(starts), -1)))
    for level in range(1, depth + 1):
        child, up = levels[level], levels[level - 1]
        parent = np.searchsorted(up.keys, child.keys >> 2)
        levels[level] = Level(child.keys, child.begins, child.ends, child.centres, child.radii, parent)
    return order, levels
