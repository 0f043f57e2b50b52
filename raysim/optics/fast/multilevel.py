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
from raysim.optics.fast.chart import Axis, Domain, axis_for, from_chart, lagrange, matrix

#: relative costs, in direct pair evaluations, of the steps' inner operations (measured roughly
#: on the CPU: a pair about 20 ns a core, a BLAS complex multiply-add well under 1 ns, an
#: elementwise numpy complex operation about 2 ns, a complex exponential about 30 ns)
COST_BLAS = 0.03
COST_NUMPY = 0.1
COST_EXP = 1.5
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
         max_depth: int = 12) -> Plan | None:
    """The cheapest (leaf, stop) levels for elements at ``positions`` (n, 3) m, or None when no
    level is separated from the targets."""
    n = len(positions)
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
            if axes[stop] is None:
                break
            if stop < leaf:  # one more aggregation step, level stop + 1 -> stop
                cu, cv = axes[stop + 1]
                pu, pv = axes[stop]
                C1 = len(levels[stop + 1].keys)
                cost += C1 * 3 * (pu.n * cu.n * cv.n + pu.n * pv.n * cv.n) * COST_BLAS
                cost += C1 * pu.n * pv.n * (COST_EXP + 3 * COST_NUMPY)
            final = len(levels[stop].keys) * M * (3 * p * p * COST_NUMPY + COST_EXP)
            if best is None or cost + final < best[0]:
                best = (cost + final, leaf, stop)
    if best is None:
        return None
    ok_axes = [a if a is not None else (Axis(0.0, 1.0, 1), Axis(0.0, 1.0, 1)) for a in axes]
    return Plan(order, levels, best[1], best[2], ok_axes, best[0], direct)


def _grid_points(axes: tuple[Axis, Axis], domain: Domain) -> NDArray[np.float64]:
    U, V = np.meshgrid(axes[0].nodes, axes[1].nodes, indexing="ij")
    return from_chart(np.column_stack([U.ravel(), V.ravel()]), domain.centre, domain.radius)


def _distances(points: NDArray[np.float64], centres: NDArray[np.float64]) -> NDArray[np.float64]:
    """(C, n) distances (m) from each centre to each point."""
    return np.sqrt(np.sum((points[None, :, :] - centres[:, None, :]) ** 2, axis=2))


def leaf_grids(segments: Any, src: NDArray[np.float64], the_plan: Plan, domain: Domain, k: float,
               device: str) -> NDArray[np.complex128]:
    """F_c (C, nu, nv, 3) of every leaf cluster on the leaf level's grid."""
    wp = runtime.init()
    from raysim.optics.kernels import radiation

    level = the_plan.levels[the_plan.leaf]
    au, av = the_plan.axes[the_plan.leaf]
    nodes = _grid_points((au, av), domain)
    n_nodes = len(nodes)
    C = len(level.keys)
    sorted_src = np.ascontiguousarray(src[:, the_plan.order])
    out = wp.zeros((6, C * n_nodes), dtype=wp.float64, device=device)
    runtime.launch(segments, C * n_nodes, [
        wp.array(np.ascontiguousarray(nodes.T), dtype=wp.float64, device=device),
        wp.array(level.begins.astype(np.int32), dtype=wp.int32, device=device),
        wp.array(level.ends.astype(np.int32), dtype=wp.int32, device=device),
        n_nodes,
        wp.array(sorted_src, dtype=wp.float64, device=device),
        k, 1.0 / k,
        wp.array(radiation.cis_table(), dtype=wp.vec2d, device=device),
        out], device, min_chunk=64)
    raw = out.numpy()
    G = (raw[:3] + 1j * raw[3:]).reshape(3, C, n_nodes)
    G = G * np.exp(1j * k * _distances(nodes, level.centres))[None]
    return np.ascontiguousarray(G.transpose(1, 2, 0)).reshape(C, au.n, av.n, 3)


def aggregate(G: NDArray[np.complex128], child: int, the_plan: Plan, domain: Domain,
              k: float, p: int, chunk_nodes: int = 4_000_000) -> NDArray[np.complex128]:
    """The parent level's grids (C0, nu, nv, 3) from the child level's ``G`` (C1, ...)."""
    low, up = the_plan.levels[child], the_plan.levels[child - 1]
    cu, cv = the_plan.axes[child]
    pu, pv = the_plan.axes[child - 1]
    Iu = matrix(pu.nodes, cu, p)
    Iv = matrix(pv.nodes, cv, p)
    nodes = _grid_points((pu, pv), domain)
    out = np.empty((len(up.keys), pu.n, pv.n, 3), dtype=np.complex128)
    # children sorted by key are grouped by parent: take whole parents per chunk
    starts = np.flatnonzero(np.r_[True, low.parent[1:] != low.parent[:-1]])
    ends = np.r_[starts[1:], len(low.parent)]
    per = max(1, chunk_nodes // max(1, pu.n * pv.n * 4))
    for g in range(0, len(starts), per):
        b, e = starts[g], ends[min(g + per, len(starts)) - 1]
        parents = low.parent[b:e]
        A = np.matmul(Iu, G[b:e].reshape(e - b, cu.n, cv.n * 3)).reshape(e - b, pu.n, cv.n, 3)
        X = np.matmul(A.transpose(0, 1, 3, 2), Iv.T).transpose(0, 1, 3, 2)  # (c, pu, pv, 3)
        shift = _distances(nodes, up.centres[parents]) - _distances(nodes, low.centres[b:e])
        X = X * np.exp(1j * k * shift).reshape(e - b, pu.n, pv.n)[..., None]
        local = starts[g:min(g + per, len(starts))] - b
        out[parents[local]] = np.add.reduceat(X, local, axis=0)
    return out


def to_targets(G: NDArray[np.complex128], the_plan: Plan, u: NDArray[np.float64],
               points: NDArray[np.float64], k: float, p: int) -> NDArray[np.complex128]:
    """The field sum (M, 3) at the targets (chart ``u`` (M, 2), ``points`` (M, 3) m) from the
    stop level's grids; elementwise per target (a block of targets gives the same bits)."""
    level = the_plan.levels[the_plan.stop]
    au, av = the_plan.axes[the_plan.stop]
    iu, wu = lagrange(u[:, 0], au, p)
    iv, wv = lagrange(u[:, 1], av, p)
    total = np.zeros((len(u), 3), dtype=np.complex128)
    for c in range(len(level.keys)):
        flat = G[c].reshape(-1, 3)
        acc = np.zeros((len(u), 3), dtype=np.complex128)
        for a in range(p):
            row = (iu + a) * av.n + iv
            inner = np.zeros((len(u), 3), dtype=np.complex128)
            for b in range(p):
                inner += wv[:, b, None] * flat[row + b]
            acc += wu[:, a, None] * inner
        r = np.sqrt(np.sum((points - level.centres[c]) ** 2, axis=1))
        total += acc * np.exp(-1j * k * r)[:, None]
    return total
