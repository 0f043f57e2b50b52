"""Warp kernels of the fast radiator (:mod:`raysim.optics.fast`): the stop level to the targets,
and the re-phasing that merges children into their parents.

In the last step each target t adds, over the clusters c given (a chunk of the stop level), the
cluster's field at it (phase of its centre taken out: the p x p Lagrange interpolation of its
refined grid, or its Fourier series summed on a tensor grid of targets) times
exp(-j k |P_t - c|) to ``out[t]``. One thread per target, clusters and chunks in a fixed order:
a target's value never depends on the other targets.
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.f64 import F64_ONE
from raysim.optics.kernels.radiation import cis, vec6d

wp.set_module_options({"enable_backward": False})


@wp.func
def dephased(acc: vec6d, P: wp.vec3d, centres: wp.array2d(dtype=wp.float64), c: int, k: wp.float64,
             table: wp.array(dtype=wp.vec2d)) -> vec6d:
    """A cluster's field at P with its centre's phase taken out, ``acc`` (Re x, Im x, Re y,
    Im y, Re z, Im z), times exp(-j k |P - c|): the field itself, as (Re x, y, z, Im x, y, z)."""
    d = P - wp.vec3d(centres[c, 0], centres[c, 1], centres[c, 2])
    e = cis(k * wp.sqrt(wp.dot(d, d)), table)  # exp(-j k r) = e[0] - j e[1]
    return vec6d(e[0] * acc[0] + e[1] * acc[1], e[0] * acc[2] + e[1] * acc[3],
                 e[0] * acc[4] + e[1] * acc[5], e[0] * acc[1] - e[1] * acc[0],
                 e[0] * acc[3] - e[1] * acc[2], e[0] * acc[5] - e[1] * acc[4])


@wp.kernel
def interpolate_targets(
    grids: wp.array4d(dtype=wp.float64),  # (C, m, m, 6): complex x, y, z as (Re, Im) pairs
    p: int,
    iu: wp.array(dtype=wp.int32),  # (M,) first stencil node along theta (may be < 0: wraps)
    iv: wp.array(dtype=wp.int32),  # (M,) along phi
    wu: wp.array2d(dtype=wp.float64),  # (M, p)
    wv: wp.array2d(dtype=wp.float64),
    centres: wp.array2d(dtype=wp.float64),  # (C, 3) m
    points: wp.array2d(dtype=wp.float64),  # (M, 3) m
    k: wp.float64,
    table: wp.array(dtype=wp.vec2d),
    out: wp.array2d(dtype=wp.float64),  # (M, 6): Re x, y, z, Im x, y, z, added to
    offset: int,
):
    t = wp.tid() + offset
    m = grids.shape[1]
    P = wp.vec3d(points[t, 0], points[t, 1], points[t, 2])
    total = vec6d()
    for c in range(grids.shape[0]):
        acc = vec6d()
        for a in range(p):
            row = ((iu[t] + a) % m + m) % m  # the grids are periodic in both angles
            inner = vec6d()
            for b in range(p):
                col = ((iv[t] + b) % m + m) % m
                w = wv[t, b]
                for q in range(6):
                    inner[q] = inner[q] + w * grids[c, row, col, q]
            acc += wu[t, a] * inner
        total += dephased(acc, P, centres, c, k, table)
    for q in range(6):
        out[t, q] = out[t, q] + total[q] * F64_ONE


@wp.kernel
def add_phased(
    series: wp.array2d(dtype=wp.float64),  # (C * M, 6): cluster c's series at target t in row c M + t
    n_targets: int,  # M
    centres: wp.array2d(dtype=wp.float64),  # (C, 3) m
    points: wp.array2d(dtype=wp.float64),  # (M, 3) m
    k: wp.float64,
    table: wp.array(dtype=wp.vec2d),
    out: wp.array2d(dtype=wp.float64),  # (M, 6): Re x, y, z, Im x, y, z, added to
    offset: int,
):
    """The last step on a tensor grid of targets: each cluster's series at the target (its
    centre's phase taken out, complex x, y, z as (Re, Im) pairs) times exp(-j k |P_t - c|),
    summed over the clusters in order and added to ``out[t]`` (one thread per target)."""
    t = wp.tid() + offset
    P = wp.vec3d(points[t, 0], points[t, 1], points[t, 2])
    total = vec6d()
    for c in range(centres.shape[0]):
        row = c * n_targets + t
        acc = vec6d(series[row, 0], series[row, 1], series[row, 2], series[row, 3], series[row, 4],
                    series[row, 5])
        total += dephased(acc, P, centres, c, k, table)
    for q in range(6):
        out[t, q] = out[t, q] + total[q]


@wp.kernel
def rephase_merge(
    fine: wp.array2d(dtype=wp.float64),  # (children * n_nodes, 6): refined child grids at the computed rows
    where: wp.array(dtype=wp.int32),  # (children,): the grid of fine that holds each child's
    n_nodes: int,  # nodes computed per grid: its rows theta <= pi
    n_full: int,  # nodes of a whole parent grid
    slots: wp.array2d(dtype=wp.int32),  # (n_nodes, 2): the whole grid's rows a node fills
    first: wp.array(dtype=wp.int32),  # (parents + 1,): children of parent q are first[q]..first[q+1]-1
    child_centres: wp.array2d(dtype=wp.float64),  # (children, 3) m
    parent_centres: wp.array2d(dtype=wp.float64),  # (parents, 3) m
    nodes: wp.array2d(dtype=wp.float64),  # (n_nodes, 3) m: the parent grid's computed points
    k: wp.float64,
    table: wp.array(dtype=wp.vec2d),
    out: wp.array2d(dtype=wp.float64),  # (parents * n_full, 6): complex pairs
    offset: int,
):
    """The parent grids: each child's refined grid times exp(+j k (|P - c_parent| - |P - c_child|)),
    summed over the children in order (one thread per computed parent node). Only the rows
    theta <= pi are computed, and the children are refined at those rows alone; each value also
    fills its mirror node (the same point of the sphere:
    :func:`raysim.optics.fast.multilevel.mirror_slots`), so the whole grid is what computing
    every node would give, at half the cost."""
    t = wp.tid() + offset
    q = t // n_nodes
    node = t - q * n_nodes
    P = wp.vec3d(nodes[node, 0], nodes[node, 1], nodes[node, 2])
    r_parent = wp.length(P - wp.vec3d(parent_centres[q, 0], parent_centres[q, 1], parent_centres[q, 2]))
    total = vec6d()
    base = first[0]
    for c in range(first[q], first[q + 1]):
        r_child = wp.length(P - wp.vec3d(child_centres[c, 0], child_centres[c, 1], child_centres[c, 2]))
        e = cis(k * (r_parent - r_child), table)  # exp(+j k (r_p - r_c)) = e[0] + j e[1]
        row = where[c - base] * n_nodes + node
        for a in range(3):
            re = fine[row, 2 * a]
            im = fine[row, 2 * a + 1]
            total[2 * a] = total[2 * a] + e[0] * re - e[1] * im
            total[2 * a + 1] = total[2 * a + 1] + e[0] * im + e[1] * re
    for j in range(2):
        slot = slots[node, j]
        if slot >= 0:
            for a in range(6):
                out[q * n_full + slot, a] = total[a]
