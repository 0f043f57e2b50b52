"""The fast radiator's quadtree against a brute-force reading of its definition: every cluster
is a contiguous range of the leaf-ordered elements sharing one cell of its level, with the
bounding-box middle as centre and the farthest element's distance as radius; and the tree
does not depend on how the elements were split into the pieces they were added in."""

from __future__ import annotations

import numpy as np
import pytest

from raysim.optics.fast import tree

DEPTH = 4


@pytest.fixture(scope="module")
def positions() -> np.ndarray:
    """Points on a paraboloid of 20 m with F 6 m (m), unevenly spread, some on the same spot."""
    rng = np.random.default_rng(5)
    r = 10.0 * np.sqrt(rng.random(3000)) ** 1.3
    phi = 2 * np.pi * rng.random(3000)
    x, y = r * np.cos(phi), r * np.sin(phi)
    pos = np.column_stack([x, y, (x * x + y * y) / 24.0])
    pos[2000:2010] = pos[7]  # coincident elements
    return pos


def _pieces(pos: np.ndarray, cuts: list[int], rows: int = 5) -> list[np.ndarray]:
    """The elements as (rows, n_i) pieces (positions then filler rows), cut at ``cuts``."""
    packed = np.vstack([pos.T, np.arange(len(pos) * (rows - 3), dtype=float).reshape(rows - 3, -1)])
    return [np.ascontiguousarray(part) for part in np.split(packed, cuts, axis=1)]


def test_clusters_are_the_cells_of_their_level(positions) -> None:
    order, levels = tree.build([positions.T], DEPTH)
    assert np.array_equal(np.sort(order), np.arange(len(positions)))
    pos = positions[order]
    lo = positions[:, :2].min(axis=0)
    side = np.max(positions[:, :2].max(axis=0) - lo)
    for level, clusters in enumerate(levels):
        cells = 2**level
        cell = np.clip(np.floor((pos[:, :2] - lo) / side * cells), 0, cells - 1).astype(int)
        cell_id = cell[:, 0] * cells + cell[:, 1]
        assert clusters.begins[0] == 0 and clusters.ends[-1] == len(pos)
        assert np.array_equal(clusters.begins[1:], clusters.ends[:-1])
        for q in range(len(clusters.keys)):
            members = slice(clusters.begins[q], clusters.ends[q])
            assert len(np.unique(cell_id[members])) == 1  # one cell per cluster ...
            box = pos[members]
            middle = 0.5 * (box.min(axis=0) + box.max(axis=0))
            assert np.allclose(clusters.centres[q], middle, rtol=0, atol=1e-12)
            radius = np.linalg.norm(box - middle, axis=1).max()
            assert clusters.radii[q] == pytest.approx(radius, rel=1e-12, abs=1e-12)
        # ... and no cell in two clusters
        firsts = cell_id[clusters.begins]
        assert len(np.unique(firsts)) == len(firsts)
        if level:
            up = levels[level - 1]
            parent = clusters.parent
            assert np.all(up.begins[parent] <= clusters.begins)
            assert np.all(clusters.ends <= up.ends[parent])


def test_the_tree_does_not_depend_on_the_pieces(positions) -> None:
    whole_order, whole = tree.build([positions.T], DEPTH)
    order, levels = tree.build(_pieces(positions, [1, 700, 701, 2500]), DEPTH)
    assert np.array_equal(order, whole_order)
    for a, b in zip(levels, whole, strict=True):
        for name in ("keys", "begins", "ends", "centres", "radii", "parent"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_gathered_puts_the_pieces_in_order_and_frees_them(positions) -> None:
    pieces = _pieces(positions, [10, 1500])
    packed = np.hstack(pieces)
    order = np.random.default_rng(1).permutation(len(positions))
    assert np.array_equal(tree.gathered(pieces, order, rows=3), positions[order].T)
    assert len(pieces) == 3  # read, not consumed
    ordered = tree.gathered(pieces, order, consume=True)
    assert np.array_equal(ordered, packed[:, order])
    assert pieces == []
    with pytest.raises(ValueError, match="order"):
        tree.gathered(_pieces(positions, []), order[:-1])
