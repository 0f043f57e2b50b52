"""The multilevel sum (Boag's MLPO idea) for one kind of element, on spectral grids of the sphere.

For a cluster of elements with centre c, F_c(P) = E_c(P) exp(+j k |P - c|) is smooth on the
target sphere (radius R about c0): its phase changes by at most B = k a R / r_min rad per rad of
angle (a the cluster's radius, r_min its least distance to the sphere), so it holds on an n x n
grid of the double-covered angles (:mod:`raysim.optics.fast.chart`) with n a little over 2 B.
One n per level (its widest cluster's), so every cluster of a level shares one grid:

1. leaves: F_c at the grid's nodes with theta <= pi by the kind's own pair function (segmented
   kernel; each pole's row, one point, once), the other rows by the sphere's symmetry;
2. up the tree: each child's grid refined to its parent's n by zero-padding its spectrum,
   re-phased by exp(+j k (|P - c_parent| - |P - c_child|)) and summed in order
   (bit-reproducible), again at the rows theta <= pi, the others by the symmetry;
3. at the stop level, times exp(-j k |P - c|) and summed over the clusters: on a tensor grid
   of targets (a sphere grid, or a block of one) each cluster's Fourier series evaluated
   exactly on the whole grid (along theta by a matrix product, along phi by an inverse FFT
   where the angles divide the turn: :func:`~raysim.optics.fast.chart.series_at`); elsewhere
   each grid refined a few times
   (the plan's ``oversampling``) and interpolated to the targets by p x p Lagrange.

The tree is walked depth first, a chunk of clusters at a time (:meth:`Plan.chunks`): a chunk of
the stop level's clusters, under it a chunk of their children, and so on to the leaves, each
chunk's grids within :data:`GRID_BYTES`; so one chunk per level is held at once and memory stays
bounded at any frequency (at 6 GHz on the paper's dish the stop level's grids alone would take
6 GB). All sums are the raw sums of :mod:`raysim.optics.kernels.radiation` (before the
prefactor).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.fft as sfft
from numpy.typing import NDArray

from raysim.optics import runtime
from raysim.optics.fast import tree as quadtree
from raysim.optics.fast.chart import (
    FFT_WORKERS,
    OVERSAMPLINGS,
    Axis,
    Domain,
    by_fft,
    degree_for,
    grid_points,
    half_rows,
    lagrange,
    mirror,
    resample,
    resample_rows,
    series_at,
    series_cost,
    size_for,
    stencil_for,
    tensor_index,
    turn_of,
)
from raysim.optics.fast.scratch import Scratch

#: costs of the steps' inner operations in units of one direct pair evaluation (the leaf kernel
#: runs the direct sum's pair function, four points in vector lanes on the CPU), measured on two
#: CPU cores (paper's dish, 1 GHz: the leaf step ran 140 M pairs/s, the aggregation 80 M of these
#: units/s with the constants before the lanes, 1.8 times too few): a p-point stencil term (six
#: real multiply-adds, scalar) about 1.2 pairs; a phase factor exp(j k r) about 2.7; a complex
#: FFT about a fifth of a pair per point and halving; an elementwise numpy complex operation
#: about a fifth; a complex multiply-add in a matrix product a twentieth (the last step's
#: products measured at the pair rate)
COST_STENCIL = 1.2
COST_EXP = 2.7
COST_FFT = 0.18
COST_NUMPY = 0.18
COST_BLAS = 0.05
#: a pair evaluation's cost in those units, per kind. PO's electric and magnetic elements run in
#: vector lanes (:mod:`raysim.optics.kernels.radiation`), the units themselves. The Jacobian's
#: shift elements do too, but their pair is heavier (an electric bracket and its derivative:
#: 24 against 79 M pairs/s on shared cores, 1.4 times their one-point kernel) and their
#: transposed sum, which shares their plan (each the exact transpose of the other), runs at
#: about 1.5 units (2.6 times its one-point kernel); a Gauss-Newton iteration runs one of
#: each, so 2.5. Other kinds (PTD's fringe elements, with their transposed sum) run one point
#: at a time, about three times as long a pair
PAIR_COST = {"electric": 1.0, "magnetic": 1.0, "shift": 2.5}
SCALAR_PAIR_COST = 3.0
GRID_BYTES = 2e8  # one level's grids held at once (a chunk of it; one chunk per level is live)
CHUNK_BYTES = 2.5e8  # refined grids held at once while aggregating or interpolating
MIN_LEAF = 8  # elements per non-empty leaf on average, at least
FALLBACK_STENCIL = stencil_for(1e-9, OVERSAMPLINGS[-1])  # a stray target of a tensor plan


@dataclass(frozen=True)
class Plan:
    """The chosen tree: ``leaf`` and ``stop`` levels, every level's grid size ``sizes[l]``
    (n x n), the last step's refinement ``oversampling`` and stencil ``p`` (both 0: the
    exact series on the domain's tensor grid), and the cost estimates (pair evaluations) of
    this plan and of the direct sum."""

    order: NDArray[np.int64]
    levels: list[quadtree.Level]
    leaf: int
    stop: int
    sizes: list[int]
    oversampling: int
    p: int
    cost: float
    direct_cost: float
    digits: float  # each step's accuracy, -log10 of its tolerance (sets the grid sizes)
    #: each leaf cluster's own grid size (at most ``sizes[leaf]``), used when the plan
    #: aggregates (stop < leaf); None: every leaf on the level's grid
    leaf_sizes: NDArray[np.int64] | None = None

    def leaf_classes(self, lo: int, hi: int) -> list[tuple[int, NDArray[np.int64]]]:
        """Leaf clusters lo .. hi - 1 in classes of one grid size: (n, their indices from lo,
        ascending), by size. One class of the level's size where the plan does not aggregate
        (its last step reads every stop grid at one size)."""
        if self.leaf_sizes is None or self.stop == self.leaf:
            return [(self.sizes[self.leaf], np.arange(hi - lo))]
        own = self.leaf_sizes[lo:hi]
        return [(int(n), np.flatnonzero(own == n)) for n in np.unique(own)]

    def children(self, level: int, q0: int, q1: int) -> tuple[int, int]:
        """The clusters of ``level + 1`` whose parents are clusters q0 .. q1 - 1 of ``level``."""
        parent = self.levels[level + 1].parent
        return int(np.searchsorted(parent, q0)), int(np.searchsorted(parent, q1))

    def chunks(self, level: int, q0: int, q1: int) -> list[tuple[int, int]]:
        """Ranges of clusters q0 .. q1 - 1 of ``level`` whose children's grids take at most
        :data:`GRID_BYTES` together (one cluster at least): the units in which the sum walks
        the tree, so that one chunk per level is held at a time however many clusters a level
        has."""
        first = np.searchsorted(self.levels[level + 1].parent, np.arange(q0, q1 + 1))
        return _runs(first, self.sizes[level + 1], q0)

    def stop_chunks(self) -> list[tuple[int, int]]:
        """Ranges of the stop level's clusters whose grids take at most :data:`GRID_BYTES`
        (one cluster at least): the chunks the sum's last step takes one after another."""
        return _runs(np.arange(len(self.levels[self.stop].keys) + 1), self.sizes[self.stop], 0)


def _runs(first: NDArray[np.int64], n: int, q0: int) -> list[tuple[int, int]]:
    """Consecutive ranges of items q0, q0 + 1, ... where item q owns the grids (n x n) numbered
    first[q - q0] .. first[q - q0 + 1] - 1, each range's grids within :data:`GRID_BYTES`."""
    per = max(1, int(GRID_BYTES // (48.0 * n * n)))
    out, q = [], 0
    while q < len(first) - 1:
        q_next = max(q + 1, int(np.searchsorted(first, first[q] + per, side="right")) - 1)
        out.append((q0 + q, q0 + q_next))
        q = q_next
    return out


def _sizes(centres: NDArray[np.float64], radii: NDArray[np.float64], domain: Domain, k: float,
           digits: float) -> NDArray[np.int64] | None:
    """The grid size n (C,) each of the clusters with ``centres`` (C, 3) m and ``radii`` (C,) m
    needs: its own bandwidth B = k a R / r_min; None when a cluster is not separated from the
    target sphere."""
    R = domain.radius
    r_min = np.linalg.norm(centres - np.asarray(domain.centre), axis=1) - R - radii
    if np.any(r_min <= 0.05 * R):
        return None  # a cluster touches the target sphere: not separated
    B = k * radii * R / r_min
    nearness = R / (R + r_min)  # R over the nearest source's distance from the sphere's centre
    degrees = np.ceil(degree_for(B, digits, nearness)).astype(np.int64)  # size_for takes its ceiling
    table = {int(d): size_for(float(d)) for d in np.unique(degrees)}
    return np.array([table[int(d)] for d in degrees], dtype=np.int64).reshape(len(B))


def _fft_cost(n: Any) -> Any:
    """A 3-component n x n grid's FFT in pair units (n a number or an array of them)."""
    return 3.0 * np.square(n) * np.maximum(np.log2(n), 1.0) * COST_FFT


def plan(pieces: Sequence[NDArray[np.float64]], domain: Domain, k: float, tol: float,
         last: tuple[tuple[int, int], ...], max_depth: int = 12, count: int | None = None,
         pair_cost: float = 1.0) -> Plan | None:
    """The cheapest (leaf, stop, last step) for the elements of ``pieces`` (rows 0..2 their
    positions, m: :func:`raysim.optics.fast.tree.build`), each level's step held to about
    ``tol``; None when no level is separated from the targets. ``last``: the (oversampling,
    stencil p) pairs the last step may use. ``count``: the number of elements when the pieces
    hold an even subset of them (a cost estimate: the tree and the costs are those of ``count``
    elements, the clusters' extents those of the subset). ``pair_cost``: what one of this
    kind's pair evaluations costs in the units of the constants above (a pair in vector lanes:
    :data:`PAIR_COST`); the direct sum's cost and the leaf step's scale with it."""
    n = sum(piece.shape[1] for piece in pieces) if count is None else int(count)
    digits = -math.log10(tol)
    depth = 0
    while depth < max_depth and n / (4 ** (depth + 1)) >= MIN_LEAF:
        depth += 1
    order, levels = quadtree.build(pieces, depth)
    each = [_sizes(level.centres, level.radii, domain, k, digits) for level in levels]
    sizes = [None if e is None else int(e.max(initial=size_for(0.0))) for e in each]
    M = domain.count
    direct = float(n) * M * pair_cost
    best: tuple[float, int, int, int, int] | None = None
    for leaf in range(depth + 1):
        nl, own = sizes[leaf], each[leaf]
        if nl is None or own is None:
            continue
        level = levels[leaf]
        # stopping at the leaves, every leaf on the level's grid (the last step reads one size);
        # aggregating, each leaf on its own grid, refined to its parent's
        nodes = half_rows(nl) * nl
        cost = float(n) * nodes * pair_cost + len(level.keys) * nodes * COST_EXP
        own_nodes = (own // 2 + 1) * own
        # the leaves' elements: of the pieces, scaled to ``count`` where they are a subset of them
        held = (level.ends - level.begins) * (n / max(len(order), 1))
        own_cost = pair_cost * float(np.dot(held, own_nodes)) + COST_EXP * float(own_nodes.sum())
        for stop in range(leaf, -1, -1):
            ns = sizes[stop]
            if ns is None:
                break
            if stop < leaf:  # one more aggregation step, level stop + 1 -> stop
                child = sizes[stop + 1]
                assert child is not None
                if stop + 1 == leaf:  # the leaves on their own grids, each refined to its parent's
                    cost = own_cost + float(np.sum(_fft_cost(own)))
                else:
                    cost += len(levels[stop + 1].keys) * _fft_cost(child)
                parents = _fft_cost(ns) + ns * ns * (COST_EXP + 4 * COST_NUMPY)
                cost += len(levels[stop + 1].keys) * parents
            for u, p in ((0, 0),) if domain.tensor else last:
                final = len(levels[stop].keys) * _last_cost(ns, u, p, domain)
                if best is None or cost + final < best[0]:
                    best = (cost + final, leaf, stop, u, p)
    if best is None:
        return None
    return Plan(order, levels, best[1], best[2], [s or 0 for s in sizes], best[3], best[4], float(best[0]),
                direct, digits, each[best[1]])


def holds(the_plan: Plan, pieces: Sequence[NDArray[np.float64]], domain: Domain, k: float) -> bool:
    """Whether the plan serves the elements of ``pieces`` (as :func:`plan`'s), taken in the
    order it was made for (the same elements moved: a deformed reflector of the same
    triangulation, a central difference's copy): every level it uses, with its clusters'
    centres kept and their radii measured on these positions, still needs grids no larger than
    the plan's. The sum is then within the tolerance for them, and it is the same linear map of
    the elements' leaf fields as for the elements it was made for."""
    if sum(piece.shape[1] for piece in pieces) != len(the_plan.order):
        return False
    coords = quadtree.gathered(pieces, the_plan.order, rows=3)  # (3, n) in leaf order
    for index in range(the_plan.stop, the_plan.leaf + 1):
        level = the_plan.levels[index]
        dist = quadtree.centre_distances(coords, level.begins, level.centres)
        radii = np.maximum.reduceat(dist, level.begins)
        if np.all(radii <= level.radii):
            continue
        need = _sizes(level.centres, np.maximum(radii, level.radii), domain, k, the_plan.digits)
        if need is None:
            return False
        own = index == the_plan.leaf and the_plan.leaf_sizes is not None and the_plan.stop < the_plan.leaf
        held = the_plan.leaf_sizes if own else the_plan.sizes[index]  # the grids each cluster sums on
        if np.any(need > held):
            return False
    return True


def _last_cost(n: int, u: int, p: int, domain: Domain) -> float:
    """Pair-equivalents of the last step for one cluster of grid size n: refinement u and
    stencil p, or (u = 0) the series on the domain's tensor grid."""
    M = domain.count
    if u == 0:  # the grid's FFT, the series along theta (3 n columns), then phi (3 R), the phases
        thetas, phis = domain.thetas or (), domain.phis or ()
        series = 3.0 * (n * series_cost(n, thetas) + len(thetas) * series_cost(n, phis))
        return _fft_cost(n) + series * COST_BLAS + M * COST_EXP
    return _fft_cost(u * n) + M * (p * p * COST_STENCIL + COST_EXP)


def warray(a: NDArray, device: str, dtype: Any = None) -> Any:
    """``a`` as a contiguous Warp array on ``device`` (float64 unless ``dtype``); on the CPU
    it shares a contiguous ``a``'s memory (and keeps it alive) rather than copying it."""
    wp = runtime.init()
    return wp.array(np.ascontiguousarray(a), dtype=dtype or wp.float64, device=device, copy=device != "cpu")


@dataclass(frozen=True)
class LeafGrids:
    """The grids of a range of leaf clusters when they are on grids of their own sizes
    (:meth:`Plan.leaf_classes`): per class, (n, the clusters' indices in the range, ascending,
    their grids (count, n, n, 3))."""

    classes: list[tuple[int, NDArray[np.int64], NDArray[np.complex128]]]


def leaf_grids(segments: Any, src: Any, the_plan: Plan, domain: Domain, k: float, device: str,
               lo: int = 0, hi: int | None = None,
               scratch: Scratch | None = None) -> NDArray[np.complex128] | LeafGrids:
    """F_c of leaf clusters lo .. hi - 1: on the leaf level's grid, (hi - lo, n, n, 3) complex,
    or, where the plan gives the leaves grids of their own sizes, a :class:`LeafGrids`.
    ``segments``: the kind's pair of kernels from :func:`raysim.optics.kernels.radiation.segment_kernel`;
    ``src``: the elements in leaf order (a Warp array of :func:`leaf_ordered`'s); ``scratch``:
    where the grids are built (role "leaf", or ("leaf", n) per class), else new arrays."""
    hi = len(the_plan.levels[the_plan.leaf].keys) if hi is None else hi
    classes = the_plan.leaf_classes(lo, hi)
    if len(classes) == 1:  # every leaf on one grid, in order
        n = classes[0][0]
        shape = (hi - lo, n, n, 3)
        full = np.empty(shape, dtype=np.complex128) if scratch is None else scratch.array("leaf", shape)
        _leaf_class(segments, src, the_plan, domain, k, device, lo + classes[0][1], n, full)
        return full
    out = []
    for n, members in classes:
        shape = (len(members), n, n, 3)
        grids = np.empty(shape, dtype=np.complex128) if scratch is None else scratch.array(("leaf", n), shape)
        _leaf_class(segments, src, the_plan, domain, k, device, lo + members, n, grids)
        out.append((n, members, grids))
    return LeafGrids(out)


def _leaf_class(segments: Any, src: Any, the_plan: Plan, domain: Domain, k: float, device: str,
                clusters: NDArray[np.int64], n: int, full: NDArray[np.complex128]) -> None:
    """F_c of the leaf ``clusters`` (indices, ascending) on the n x n grid, into ``full``
    (len(clusters), n, n, 3): the kind's pair function at the rows theta <= pi (four nodes a
    thread on the CPU), each value also written to its mirror node, each pole once
    (:func:`distinct_nodes`)."""
    wp = runtime.init()
    from raysim.optics.kernels import radiation

    level = the_plan.levels[the_plan.leaf]
    distinct = distinct_nodes(n)
    nodes = grid_points(n, domain, half_rows(n))[distinct]
    n_nodes = len(nodes)
    tile = 4 if device == "cpu" else 1  # as the direct radiator: four nodes a thread on the CPU
    n_pad = -(-n_nodes // tile) * tile  # pad with copies of the last node
    padded = np.vstack([nodes, np.repeat(nodes[-1:], n_pad - n_nodes, axis=0)])
    slots = np.full((n_pad, 2), -1, dtype=np.int32)
    slots[:n_nodes] = mirror_slots(n, half_rows(n) * n)[distinct]
    C = len(clusters)
    E = full.reshape(C * n * n, 3).view(np.float64)  # (C n^2, 6): the kernel writes each node once
    out = warray(E, device) if device == "cpu" else wp.empty(E.shape, dtype=wp.float64, device=device)
    runtime.launch(segments[1] if tile == 4 else segments[0], C * n_pad // tile, [
        warray(padded.T, device), warray(level.begins[clusters].astype(np.int32), device, wp.int32),
        warray(level.ends[clusters].astype(np.int32), device, wp.int32),
        warray(level.centres[clusters], device),
        n_pad, src, k, 1.0 / k, warray(radiation.cis_table(), device, wp.vec2d),
        warray(slots, device, wp.int32), n * n, out], device, min_chunk=16)
    if device != "cpu":
        E[...] = out.numpy()
    h = n // 2
    full[:, (0, h), 1:, :] = full[:, (0, h), :1, :]  # each pole's value along its row


def distinct_nodes(n: int) -> NDArray[np.int64]:
    """The computed nodes of an n x n grid (its rows theta <= pi, row-major) that are distinct
    points of the sphere: the rows theta = 0 and theta = pi are one point each, the poles (a
    leaf's field there is computed once, at the row's first node, and copied along it: 2 n - 2
    fewer nodes, 7 % of a leaf of n = 56)."""
    h = n // 2
    return np.r_[0, n:h * n, h * n]


def mirror_slots(n: int, n_pad: int) -> NDArray[np.int32]:
    """(n_pad, 2): for each computed node of an n x n grid (its rows theta <= pi, row-major,
    padded to n_pad) the whole grid's nodes it fills, by :func:`~raysim.optics.fast.chart.mirror`:
    its own place, and the node of the mirrored rows that is the same point of the sphere
    (-1: none; padding nodes fill nothing)."""
    computed = half_rows(n) * n
    source = mirror(np.arange(computed).reshape(half_rows(n), n, 1), n).reshape(-1)  # whole grid <- node
    slots = np.full((n_pad, 2), -1, dtype=np.int32)
    slots[:computed, 0] = np.arange(computed)  # rows theta <= pi are the whole grid's first rows
    twins = np.arange(computed, n * n)
    slots[source[twins], 1] = twins
    return slots


def aggregate(G: NDArray[np.complex128] | LeafGrids, child: int, the_plan: Plan, domain: Domain, k: float,
              device: str, q_lo: int = 0, q_hi: int | None = None, into: NDArray[np.complex128] | None = None,
              scratch: Scratch | None = None) -> NDArray[np.complex128]:
    """The grids (q_hi - q_lo, n, n, 3) of parents q_lo .. q_hi - 1 (level ``child - 1``) from
    ``G`` (their children's grids, in order, or leaves on grids of their own sizes): spectra
    zero-padded (whole families at a time), re-phased and summed in order. ``into``: the array
    to write them to (returned), else a new one; ``scratch``: buffers for the refined
    children, and then ``G`` is overwritten."""
    wp = runtime.init()
    from raysim.optics.kernels import fast, radiation

    low, up = the_plan.levels[child], the_plan.levels[child - 1]
    n = the_plan.sizes[child - 1]
    n_half = half_rows(n) * n  # the nodes computed; the kernel fills their mirrors too
    nodes = warray(grid_points(n, domain, half_rows(n)), device)
    slots = warray(mirror_slots(n, n_half), device, wp.int32)
    table = warray(radiation.cis_table(), device, wp.vec2d)
    q_hi = len(up.keys) if q_hi is None else q_hi
    C0 = q_hi - q_lo
    base = int(np.searchsorted(low.parent, q_lo))  # G's first child in the level's numbering
    first = (np.searchsorted(low.parent, np.arange(q_lo, q_hi + 1)) - base).astype(np.int32)  # into G
    out = np.empty((C0, n, n, 3), dtype=np.complex128) if into is None else into
    if not out.flags.c_contiguous:  # the kernel writes into its memory through a flat view
        raise ValueError("aggregate: 'into' must be C-contiguous")
    per = max(1, int(CHUNK_BYTES // (48 * n * n * 2)))  # children refined at once
    q = 0
    while q < C0:  # whole families at a time, so each parent is summed in one place
        q1 = q + 1
        while q1 < C0 and first[q1 + 1] - first[q] <= per:
            q1 += 1
        c0, c1 = int(first[q]), int(first[q1])
        fine, where = _refined(G, c0, c1, n, scratch)
        target = out[q:q1].reshape(-1, 3).view(np.float64)  # ((q1 - q) n^2, 6)
        part = warray(target, device) if device == "cpu" else wp.empty(target.shape, dtype=wp.float64,
                                                                         device=device)
        runtime.launch(fast.rephase_merge, (q1 - q) * n_half, [
            warray(fine, device), warray(where, device, wp.int32), n_half, n * n, slots,
            warray(first[q:q1 + 1], device, wp.int32),
            warray(low.centres[base:], device), warray(up.centres[q_lo + q:q_lo + q1], device), nodes, k,
            table, part], device, min_chunk=256)
        if device != "cpu":
            target[...] = part.numpy()
        q = q1
    return out


def _refined(G: NDArray[np.complex128] | LeafGrids, c0: int, c1: int, n: int,
             scratch: Scratch | None) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """Children c0 .. c1 - 1 of ``G`` refined to n x n, at the rows theta <= pi the parents
    compute (:func:`~raysim.optics.fast.chart.resample_rows`): (their grids, (c1 - c0)
    half_rows(n) n rows of six reals, one class of grid size after another; where each child's
    grid is in them)."""
    rows = half_rows(n)
    shape = (c1 - c0, rows, n, 3)
    fine = np.empty(shape, dtype=np.complex128) if scratch is None else scratch.array("fine", shape)
    overwrite = scratch is not None
    if not isinstance(G, LeafGrids):
        refined = resample_rows(G[c0:c1], n, rows, out=fine, scratch=scratch, overwrite=overwrite)
        if not np.may_share_memory(refined, fine):  # the grids were already n x n
            fine[...] = refined
        return fine.view(np.float64).reshape(-1, 6), np.arange(c1 - c0, dtype=np.int32)
    where = np.empty(c1 - c0, dtype=np.int32)
    at = 0
    for _, members, grids in G.classes:
        i0, i1 = np.searchsorted(members, (c0, c1))
        if i1 == i0:
            continue
        block = fine[at:at + i1 - i0]
        refined = resample_rows(grids[i0:i1], n, rows, out=block, scratch=scratch, overwrite=overwrite)
        if not np.may_share_memory(refined, block):  # the transform returned a new array
            block[...] = refined
        where[members[i0:i1] - c0] = np.arange(at, at + i1 - i0)
        at += i1 - i0
    return fine.view(np.float64).reshape(-1, 6), where


def leaf_ordered(pieces: list[NDArray[np.float64]], the_plan: Plan) -> NDArray[np.float64]:
    """The elements of ``pieces`` ((rows, n_i) each, in the order the plan was made for) as one
    (rows, n) array in the plan's leaf order (:func:`raysim.optics.fast.tree.gathered`). The
    list is emptied as it is read: a piece nothing else holds is freed once it is copied, so
    the elements are held about once, not twice, while they are gathered."""
    return quadtree.gathered(pieces, the_plan.order, consume=True)


def stop_grids(segments: Any, ordered: NDArray[np.float64], the_plan: Plan, domain: Domain, k: float,
               device: str) -> Iterator[tuple[int, int, NDArray[np.complex128]]]:
    """The stop level's grids of the elements ``ordered`` (the kind's packed rows, in the plan's
    leaf order: :func:`leaf_ordered`), a chunk of clusters at a time: (q0, q1, grids (q1 - q0,
    n, n, 3)) of clusters q0 .. q1 - 1, each a new array (a caller may keep them). Each chunk
    is summed from the leaves up one chunk of families per level at a time
    (:meth:`Plan.chunks`), so the memory held is a chunk per level whatever the frequency; the
    levels below the stop level reuse their buffers from chunk to chunk
    (:class:`~raysim.optics.fast.scratch.Scratch`)."""
    sorted_src = warray(ordered, device)
    scratch = Scratch()
    for q0, q1 in the_plan.stop_chunks():
        yield q0, q1, _grids(segments, sorted_src, the_plan, domain, k, device, the_plan.stop, q0, q1,
                             scratch)


def _grids(segments: Any, sorted_src: Any, the_plan: Plan, domain: Domain, k: float, device: str,
           level: int, q0: int, q1: int, scratch: Scratch) -> NDArray[np.complex128]:
    """The grids (q1 - q0, n, n, 3) of clusters q0 .. q1 - 1 of ``level``: at the leaves by
    the kernel, above from their children, a chunk of families at a time. Below the stop
    level they are built in ``scratch`` (role ("level", level): read by the level above
    before this level is asked for again); the stop level's are a new array."""
    if level == the_plan.leaf:
        return leaf_grids(segments, sorted_src, the_plan, domain, k, device, q0, q1,
                          scratch if level != the_plan.stop else None)
    n = the_plan.sizes[level]
    shape = (q1 - q0, n, n, 3)
    if level == the_plan.stop:
        out = np.empty(shape, dtype=np.complex128)
    else:
        out = scratch.array(("level", level), shape)
    for p0, p1 in the_plan.chunks(level, q0, q1):
        part = _grids(segments, sorted_src, the_plan, domain, k, device, level + 1,
                      *the_plan.children(level, p0, p1), scratch)
        aggregate(part, level + 1, the_plan, domain, k, device, p0, p1, into=out[p0 - q0:p1 - q0],
                  scratch=scratch)
    return out


def target_axis(n: int, p: int) -> Axis:
    """The axis of a refined grid of n nodes over [0, 2 pi), seen padded by p periodic nodes
    each side (so every target's stencil is centred; the kernel wraps the indices)."""
    h = 2.0 * np.pi / n
    return Axis(-p * h, h, n + 2 * p)


def to_targets(grids: Callable[[], Iterable[tuple[int, int, NDArray[np.complex128]]]], the_plan: Plan,
               angles: NDArray[np.float64], points: NDArray[np.float64], k: float, device: str,
               domain: Domain, store: dict | None = None) -> NDArray[np.float64]:
    """The raw sums (M, 6) at the targets (``angles`` (M, 2) theta, phi rad; ``points`` (M, 3)
    m, on ``domain``'s sphere) from the stop level's grids, which ``grids()`` yields a chunk at
    a time (:func:`stop_grids`). ``store``: where the sums on the whole tensor grid are kept
    between blocks (the owner's cache). Every target's value is the same whatever block it
    comes in."""
    if the_plan.oversampling == 0:
        index = tensor_index(angles, domain)
        if index is not None:
            store = {} if store is None else store
            if "grid" not in store:
                store["grid"] = grid_sums(grids(), the_plan, domain, k)
            return store["grid"][index]
        the_plan = general_last_step(the_plan)  # a target off the tensor grid
    return interpolated(grids(), the_plan, angles, points, k, device)


def grid_sums(grids: Iterable[tuple[int, int, NDArray[np.complex128]]], the_plan: Plan, domain: Domain,
              k: float) -> NDArray[np.float64]:
    """The raw sums (R * Q, 6) on ``domain``'s whole tensor grid (R thetas x Q phis, row-major):
    each cluster's Fourier series (its grid's FFT, the Nyquist row and column dropped) summed
    at the grid's thetas, then at its phis (:func:`~raysim.optics.fast.chart.series_at`: inverse
    FFTs where the angles are uniform and their step divides the turn, as a sphere grid's do),
    then times exp(-j k |P - c|) and summed over the clusters in order, target by target
    (:func:`raysim.optics.kernels.fast.add_phased`).

    The series of one chunk of stop grids are summed on a second thread while the next chunk
    is built (the aggregation's kernels and transforms), so this step's numpy work, mostly on
    one core, overlaps work that keeps both busy; the chunks are still summed one after
    another in order, so the bits are those of a plain loop."""
    wp = runtime.init()
    from raysim.optics.kernels import radiation

    points = tensor_points(domain)
    out = wp.zeros((len(points), 6), dtype=wp.float64, device="cpu")
    shared = (warray(points, "cpu"), warray(radiation.cis_table(), "cpu", wp.vec2d))
    with ThreadPoolExecutor(max_workers=1) as summer:
        pending = None
        for q0, q1, G in grids:
            if pending is not None:
                pending.result()  # one chunk summed at a time: at most two chunks of grids held
            pending = summer.submit(_add_series, out, G, q0, q1, the_plan, domain, shared, k)
        if pending is not None:
            pending.result()
    return out.numpy()


def _add_series(out: Any, G: NDArray[np.complex128], q0: int, q1: int, the_plan: Plan, domain: Domain,
                shared: tuple[Any, Any], k: float) -> None:
    """Add the series of stop clusters q0 .. q1 - 1 (their grids ``G``) on ``domain``'s tensor
    grid to ``out`` (R * Q, 6), a few clusters at a time (:data:`CHUNK_BYTES`), in order;
    ``shared``: the grid's points and the phase table as Warp arrays."""
    from raysim.optics.kernels import fast

    level = the_plan.levels[the_plan.stop]
    n = the_plan.sizes[the_plan.stop]
    thetas, phis = domain.thetas, domain.phis
    assert thetas is not None and phis is not None
    M = len(thetas) * len(phis)
    # a cluster's transforms: its spectrum, the series at the thetas over a whole period, then
    # at the phis over a whole period (the periods, or the counts where the angles are no Turn)
    # (the period where that axis's series runs as an FFT, the angles' count where as a product)
    extent = [t.period if (t := turn_of(a)) is not None and by_fft(n, t, len(a)) else len(a)
              for a in (thetas, phis)]
    held = n * n + extent[0] * n + len(thetas) * extent[1]
    per = max(1, int(CHUNK_BYTES // (48 * held)))
    for c0 in range(q0, q1, per):
        c1 = min(c0 + per, q1)
        S = sfft.fft2(G[c0 - q0:c1 - q0], axes=(1, 2), workers=FFT_WORKERS)
        S *= 1.0 / (n * n)
        W = np.ascontiguousarray(series_at(series_at(S, 1, thetas), 2, phis))  # (c, R, Q, 3)
        del S
        runtime.launch(fast.add_phased, M, [
            warray(W.view(np.float64).reshape(-1, 6), "cpu"), M, warray(level.centres[c0:c1], "cpu"),
            shared[0], k, shared[1], out], "cpu", min_chunk=256)


def series_basis(n: int, domain: Domain) -> tuple[NDArray[np.int64], NDArray[np.complex128],
                                                 NDArray[np.complex128]]:
    """(keep, E_theta (R, n - 1), E_phi_T (n - 1, Q)): the kept coefficients of an n x n grid's
    FFT (the Nyquist ones dropped) and exp(j m angle) at the tensor grid's thetas and phis for
    their signed frequencies m, so that the series on the grid is E_theta S E_phi_T."""
    h = n // 2
    keep = np.r_[0:h, n - h + 1:n]
    freqs = np.r_[0:h, -(h - 1):0]
    E_theta = np.exp(1j * np.outer(np.asarray(domain.thetas), freqs))
    E_phi_T = np.exp(1j * np.outer(freqs, np.asarray(domain.phis)))
    return keep, E_theta, E_phi_T


def distances(points: NDArray[np.float64], centres: NDArray[np.float64]) -> NDArray[np.float64]:
    """|P - c| (C, m) m for every centre (C, 3) and point (m, 3): the squares summed a
    coordinate at a time (x, then y, then z), in place (a (C, m, 3) temporary summed along its
    short last axis takes ten times as long)."""
    out = np.zeros((len(centres), len(points)))
    for axis in range(3):
        step = np.subtract.outer(centres[:, axis], points[:, axis])  # (c - P)^2 = (P - c)^2 exactly
        out += np.square(step, out=step)
    return np.sqrt(out, out=out)


def tensor_points(domain: Domain) -> NDArray[np.float64]:
    """The points (R * Q, 3) m of ``domain``'s tensor grid, row-major (theta, then phi)."""
    thetas, phis = np.asarray(domain.thetas), np.asarray(domain.phis)
    s = np.sin(thetas)[:, None]
    dirs = np.stack([s * np.cos(phis)[None, :], s * np.sin(phis)[None, :],
                     -np.cos(thetas)[:, None] * np.ones((1, len(phis)))], axis=-1).reshape(-1, 3)
    return np.asarray(domain.centre) + domain.radius * dirs


def general_last_step(the_plan: Plan) -> Plan:
    """``the_plan`` with the general last step (refined grid, Lagrange) at its finest setting:
    for a target off the tensor grid a plan was made for."""
    return replace(the_plan, oversampling=OVERSAMPLINGS[-1], p=FALLBACK_STENCIL)


def interpolated(grids: Iterable[tuple[int, int, NDArray[np.complex128]]], the_plan: Plan,
                 angles: NDArray[np.float64], points: NDArray[np.float64], k: float,
                 device: str) -> NDArray[np.float64]:
    """The raw sums (M, 6) at any targets: each stop grid refined ``the_plan.oversampling``
    times and interpolated by p x p Lagrange; one thread per target, clusters in a fixed order
    (a block of targets gives the same bits)."""
    wp = runtime.init()
    from raysim.optics.kernels import fast, radiation

    level = the_plan.levels[the_plan.stop]
    p = the_plan.p
    m = the_plan.oversampling * the_plan.sizes[the_plan.stop]
    axis = target_axis(m, p)
    iu, wu = lagrange(angles[:, 0], axis, p)
    iv, wv = lagrange(angles[:, 1], axis, p)
    args = [warray(iu - p, device, wp.int32), warray(iv - p, device, wp.int32), warray(wu, device),
            warray(wv, device)]
    pts, table = warray(points, device), warray(radiation.cis_table(), device, wp.vec2d)
    out = wp.zeros((len(angles), 6), dtype=wp.float64, device=device)
    per = max(1, int(CHUNK_BYTES // (48 * m * m * 2)))
    scratch = Scratch()
    for q0, q1, G in grids:
        for c0 in range(q0, q1, per):
            c1 = min(c0 + per, q1)
            # (c, m, m, 6): (Re, Im) pairs; G is not overwritten (an owner may keep it)
            buffer = scratch.array("fine", (c1 - c0, m, m, 3))
            fine = resample(G[c0 - q0:c1 - q0], m, out=buffer).view(np.float64)
            runtime.launch(fast.interpolate_targets, len(angles), [
                warray(fine, device), p, *args, warray(level.centres[c0:c1], device), pts, k, table, out],
                device, min_chunk=16)
    return out.numpy()
