"""Warp kernels of the fast radiator's transposed sum (:mod:`raysim.optics.fast.adjoint`).

The transposed steps between the grids are FFTs and matrix products (numpy, scipy); what runs
here is per (cluster, point): a cluster centre's phase applied to weights on points. Every
output value is written by exactly one thread: the same bits however a launch is split.
Complex 3-vectors travel as (Re x, y, z, Im x, y, z).
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.radiation import cis

wp.set_module_options({"enable_backward": False})


@wp.kernel
def phase_rows(
    points: wp.array2d(dtype=wp.float64),  # (M, 3) m
    values: wp.array3d(dtype=wp.float64),  # (C or 1, M, 6): one set per cluster, or one for all
    centres: wp.array2d(dtype=wp.float64),  # (C, 3) m
    sign: wp.float64,  # -1: exp(-j k r) (targets); +1: exp(+j k r) (a leaf centre's phase put back)
    k: wp.float64,
    table: wp.array(dtype=wp.vec2d),
    out: wp.array3d(dtype=wp.float64),  # (C, M, 6)
    offset: int,
):
    """out[c, t] = exp(sign j k |P_t - c|) values[c or 0, t]: one thread per (cluster, point)."""
    t = wp.tid() + offset
    m = points.shape[0]
    c = t // m
    i = t - c * m
    cv = c
    if values.shape[0] == 1:
        cv = 0
    d = wp.vec3d(points[i, 0], points[i, 1], points[i, 2]) - wp.vec3d(centres[c, 0], centres[c, 1],
                                                                      centres[c, 2])
    e = cis(k * wp.length(d), table)
    er = e[0]
    ei = sign * e[1]
    for q in range(3):
        vr = values[cv, i, q]
        vi = values[cv, i, q + 3]
        out[c, i, q] = er * vr - ei * vi
        out[c, i, q + 3] = er * vi + ei * vr


@wp.kernel
def rephase_split(
    beta: wp.array2d(dtype=wp.float64),  # (parents * n_nodes, 6): parent grid weights, complex pairs
    n_nodes: int,
    parent: wp.array(dtype=wp.int32),  # (children,): each child's parent, an index into beta's grids
    child_centres: wp.array2d(dtype=wp.float64),  # (children, 3) m
    parent_centres: wp.array2d(dtype=wp.float64),  # (parents, 3) m
    nodes: wp.array2d(dtype=wp.float64),  # (n_nodes, 3) m: the parent grid's points
    k: wp.float64,
    table: wp.array(dtype=wp.vec2d),
    out: wp.array2d(dtype=wp.float64),  # (children * n_nodes, 6): complex pairs
    offset: int,
):
    """Each child's weights on its parent's grid: the parent's times
    exp(+j k (|P - c_parent| - |P - c_child|)) (the transpose of the forward's re-phasing;
    one thread per child node). Complex 3-vectors as (Re x, Im x, Re y, Im y, Re z, Im z)."""
    t = wp.tid() + offset
    c = t // n_nodes
    node = t - c * n_nodes
    q = parent[c]
    P = wp.vec3d(nodes[node, 0], nodes[node, 1], nodes[node, 2])
    r_parent = wp.length(P - wp.vec3d(parent_centres[q, 0], parent_centres[q, 1], parent_centres[q, 2]))
    r_child = wp.length(P - wp.vec3d(child_centres[c, 0], child_centres[c, 1], child_centres[c, 2]))
    e = cis(k * (r_parent - r_child), table)  # exp(+j k (r_p - r_c)) = e[0] + j e[1]
    row = q * n_nodes + node
    for a in range(3):
        re = beta[row, 2 * a]
        im = beta[row, 2 * a + 1]
        out[t, 2 * a] = e[0] * re - e[1] * im
        out[t, 2 * a + 1] = e[0] * im + e[1] * re
