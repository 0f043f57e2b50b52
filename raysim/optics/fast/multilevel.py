"""The multilevel sum (Boag's MLPO idea) for one kind of element, on the chart of a target sphere.

For a cluster of elements with centre c, F_c(P) = E_c(P) exp(+j k |P - c|) is smooth on the
target sphere: its phase changes with the chart coordinate u at most B = 2 R (k a + 1) / r_min
rad per unit (a the cluster's radius, r_min its least distance to the sphere; the +1 bounds the
amplitude's change). Each level samples every cluster's F_c on one uniform chart grid of
spacing pi / (B s) over the whole target box (s the oversampling), so one pair of Lagrange
matrices serves every cluster of a level:

1. leaves: F_c at the leaf grid's nodes by the kind's own pair function (segmented kernel);
2. up the tree: each child's grid interpolated to its parent's finer grid, re-phased by
   exp(+j k (|P - c_parent| - |P - c_child|)) and summed (fixed order: bit-reproducible);
3. at the stop level: every cluster interpolated to the targets, times exp(-j k |P - c|).

All sums are the raw sums of :mod:`raysim.optics.kernels.radiation` (before the prefactor).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from raysim.optics import runtime
from raysim.optics.fast import tree as quadtree
from raysim.optics.fast.chart import Axis, Domain, axis_for, from_chart, lagrange

#: costs of the steps' inner operations in units of one direct pair evaluation (the leaf kernel
#: runs the direct sum's pair function), measured on two CPU cores (paper's dish, 0.3 GHz):
#: a p-point stencil term (six real multiply-adds, as the interpolation kernels run them) about
#: a third of a pair; a phase factor exp(j k r) from the table about one and a half
COST_STENCIL = 0.33
COST_EXP = 1.5
MEMORY_BYTES = 3e9  # the largest level's grids (two levels are held at once), at most
MIN_LEAF = 8  # elements per non-empty leaf on average, at least
AMPLITUDE = 6.0  # rad per unit of 2 R / r_min: the amplitude's and near-field terms' change


@dataclass(frozen=True)
class Plan:
    """The chosen tree: ``leaf`` and ``stop`` levels, every level's chart axes, and the cost
    estimates (pair evaluations) of this plan and of the direct sum."""

    order: NDArray[np.int64]
    levels: list[quadtree.Level]
    leaf: int
    stop: int
    axes: list[tuple[Axis, Axis]]
    cost: float
    direct_cost: float


def _axes(level: quadtree.Level, domain: Domain, k: float, s: float, p: int) -> tuple[Axis, Axis] | None:
    R = domain.radius
    r_min = np.linalg.norm(level.centres - np.asarray(domain.centre), axis=1) - R - level.radii
    if np.any(r_min <= 0.05 * R):
        return None  # a cluster touches the target sphere: not separated
    B = float(np.max(2.0 * R * (k * level.radii + AMPLITUDE) / r_min))
    h = np.pi / (B * s)
    box = domain.box
    return axis_for(box[0], box[1], h, p), axis_for(box[2], box[3], h, p)


def plan(positions: NDArray[np.float64], domain: Domain, k: float, p: int, s: float,
         max_depth: int = 12, count: int | None = None) -> Plan | None:
    """The cheapest (leaf, stop) levels for elements at ``positions`` (n, 3) m, or None when no
    level is separated from the targets. ``count``: the number of elements when ``positions``
    is an even subset of them (a cost estimate: the tree and the costs are those of ``count``
    elements, the clusters' extents those of the subset)."""
    n = len(positions) if count is None else int(count)
    depth = 0
    while depth < max_depth and n / (4 ** (depth + 1)) >= MIN_LEAF:
        depth += 1
    order, levels = quadtree.build(positions, depth)
    axes = [_axes(level, domain, k, s, p) for level in levels]
    M = domain.count
    direct = float(n) * M
    best: tuple[float, int, int] | None = None
    for leaf in range(depth + 1):
        if axes[leaf] is None:
            continue
        nodes = axes[leaf][0].n * axes[leaf][1].n
        cost = float(n) * nodes + len(levels[leaf].keys) * nodes * COST_EXP
        for stop in range(leaf, -1, -1):
            if axes[stop] is None or 48.0 * len(levels[stop].keys) * axes[stop][0].n * axes[stop][1].n \
                    > MEMORY_BYTES:
                break
            if stop < leaf:  # one more aggregation step, level stop + 1 -> stop
                cost += _aggregation_cost(len(levels[stop + 1].keys), axes[stop + 1], axes[stop], p)
            final = len(levels[stop].keys) * M * (p * p * COST_STENCIL + COST_EXP)
            if best is None or cost + final < best[0]:
                best = (cost + final, leaf, stop)
    if best is None:
        return None
    ok_axes = [a if a is not None else (Axis(0.0, 1.0, 1), Axis(0.0, 1.0, 1)) for a in axes]
    return Plan(order, levels, best[1], best[2], ok_axes, best[0], direct)


def _aggregation_cost(children: int, child: tuple[Axis, Axis], parent: tuple[Axis, Axis], p: int) -> float:
    """Pair-equivalents of one aggregation step as :func:`aggregate` runs it: a p-point stencil
    along u for every (parent u, child v) node of each child, one along v for every parent node
    of each child, and two phase factors per parent node and child."""
    cv, (pu, pv) = child[1], parent
    stencils = children * p * (pu.n * cv.n + pu.n * pv.n)
    return stencils * COST_STENCIL + 2.0 * children * pu.n * pv.n * COST_EXP


def _grid_points(axes: tuple[Axis, Axis], domain: Domain) -> NDArray[np.float64]:
    U, V = np.meshgrid(axes[0].nodes, axes[1].nodes, indexing="ij")
    return from_chart(np.column_stack([U.ravel(), V.ravel()]), domain.centre, domain.radius)


def _arr(a: NDArray, device: str, dtype: Any = None) -> Any:
    wp = runtime.init()
    return wp.array(np.ascontiguousarray(a), dtype=dtype or wp.float64, device=device)


def leaf_grids(segments: Any, src: NDArray[np.float64], the_plan: Plan, domain: Domain, k: float,
               device: str) -> NDArray[np.float64]:
    """F_c of every leaf cluster on the leaf level's grid: (C, nu * nv, 6) Re x, y, z, Im x, y, z.
    ``segments``: the kind's pair of kernels from :func:`raysim.optics.kernels.radiation.segment_kernel`."""
    wp = runtime.init()
    from raysim.optics.kernels import radiation

    level = the_plan.levels[the_plan.leaf]
    au, av = the_plan.axes[the_plan.leaf]
    nodes = _grid_points((au, av), domain)
    n_nodes = len(nodes)
    tile = 4 if device == "cpu" else 1  # as the direct radiator: four nodes a thread on the CPU
    n_pad = -(-n_nodes // tile) * tile  # pad with copies of the last node
    padded = np.vstack([nodes, np.repeat(nodes[-1:], n_pad - n_nodes, axis=0)])
    C = len(level.keys)
    out = wp.zeros((C * n_pad, 6), dtype=wp.float64, device=device)
    runtime.launch(segments[1] if tile == 4 else segments[0], C * n_pad // tile, [
        _arr(padded.T, device), _arr(level.begins.astype(np.int32), device, wp.int32),
        _arr(level.ends.astype(np.int32), device, wp.int32), _arr(level.centres, device), n_pad,
        _arr(src[:, the_plan.order], device), k, 1.0 / k,
        _arr(radiation.cis_table(), device, wp.vec2d), out], device, min_chunk=16)
    return np.ascontiguousarray(out.numpy().reshape(C, n_pad, 6)[:, :n_nodes])


def aggregate(G: NDArray[np.float64], child: int, the_plan: Plan, domain: Domain, k: float, p: int,
              device: str) -> NDArray[np.float64]:
    """The parent level's grids (C0, nu * nv, 6) from the child level's ``G`` (C1, ..., 6):
    separable Lagrange interpolation (u, then v), re-phasing, children summed in order."""
    wp = runtime.init()
    from raysim.optics.kernels import fast, radiation

    low, up = the_plan.levels[child], the_plan.levels[child - 1]
    cu, cv = the_plan.axes[child]
    pu, pv = the_plan.axes[child - 1]
    iu, wu = lagrange(pu.nodes, cu, p)
    iv, wv = lagrange(pv.nodes, cv, p)
    C1, C0 = len(low.keys), len(up.keys)
    half = wp.zeros((C1, pu.n * cv.n, 6), dtype=wp.float64, device=device)
    runtime.launch(fast.interpolate_u, C1 * pu.n * cv.n, [
        _arr(G, device), cv.n, p, _arr(iu.astype(np.int32), device, wp.int32), _arr(wu, device), half],
        device, min_chunk=256)
    first = np.searchsorted(low.parent, np.arange(C0 + 1)).astype(np.int32)
    out = wp.zeros((C0, pu.n * pv.n, 6), dtype=wp.float64, device=device)
    runtime.launch(fast.interpolate_v_merge, C0 * pu.n * pv.n, [
        half, cv.n, p, _arr(iv.astype(np.int32), device, wp.int32), _arr(wv, device),
        _arr(first, device, wp.int32), _arr(low.centres, device), _arr(up.centres, device),
        _arr(_grid_points((pu, pv), domain), device), k,
        _arr(radiation.cis_table(), device, wp.vec2d), out], device, min_chunk=256)
    return out.numpy()


def to_targets(G: NDArray[np.complex128], the_plan: Plan, u: NDArray[np.float64],
               points: NDArray[np.float64], k: float, p: int, device: str) -> NDArray[np.float64]:
    """The raw sums (M, 6) at the targets (chart ``u`` (M, 2), ``points`` (M, 3) m) from the
    stop level's grids; one thread per target (a block of targets gives the same bits)."""
    wp = runtime.init()
    from raysim.optics.kernels import fast, radiation

    level = the_plan.levels[the_plan.stop]
    au, av = the_plan.axes[the_plan.stop]
    iu, wu = lagrange(u[:, 0], au, p)
    iv, wv = lagrange(u[:, 1], av, p)
    grids = G

    def arr(a: NDArray, dtype: Any = None) -> Any:
        return _arr(a, device, dtype)

    out = wp.zeros((len(u), 6), dtype=wp.float64, device=device)
    runtime.launch(fast.interpolate_targets, len(u), [
        arr(grids), av.n, p, arr(iu.astype(np.int32), wp.int32), arr(iv.astype(np.int32), wp.int32),
        arr(wu), arr(wv), arr(level.centres), arr(points), k,
        arr(radiation.cis_table(), wp.vec2d), out], device, min_chunk=16)
    return out.numpy()
