"""Warp kernels of the fast radiator's transposed sum (:mod:`raysim.optics.fast.adjoint`).

The forward kernels (:mod:`raysim.optics.kernels.fast`) interpolate grids to finer grids and to
the targets; these apply the transposes (anterpolation): weights on the targets are spread onto
the stop level's chart grids, and each parent's grid is re-phased per child and spread onto the
child's grid. Every output value is written by exactly one thread, which sums its terms in a
fixed order (gathers over CSR lists, or a thread that owns a whole output row): no atomics, the
same bits however a launch is split. Complex 3-vectors travel as (Re x, y, z, Im x, y, z).
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.radiation import cis, vec6d

wp.set_module_options({"enable_backward": False})


@wp.kernel
def anterpolate_targets(
    weights: wp.array3d(dtype=wp.float64),  # (C, M, 6): b_t exp(-j k |P_t - c|) per stop cluster
    indptr: wp.array(dtype=wp.int32),  # (n_nodes + 1,) CSR over the stop grid's nodes
    targets: wp.array(dtype=wp.int32),  # (nnz,) the targets whose stencil covers the node
    lagrange: wp.array(dtype=wp.float64),  # (nnz,) their weights wu * wv at the node
    out: wp.array3d(dtype=wp.float64),  # (C, n_nodes, 6)
    offset: int,
):
    """beta_c(node) = sum_t W(t, node) weights[c, t]: one thread per (cluster, node)."""
    t = wp.tid() + offset
    n_nodes = indptr.shape[0] - 1
    c = t // n_nodes
    node = t - c * n_nodes
    acc = vec6d()
    for e in range(indptr[node], indptr[node + 1]):
        w = lagrange[e]
        i = targets[e]
        for q in range(6):
            acc[q] = acc[q] + w * weights[c, i, q]
    for q in range(6):
        out[c, node, q] = acc[q]


@wp.kernel
def rephase_anterpolate_v(
    beta: wp.array3d(dtype=wp.float64),  # (C_parent, nu_parent * nv_parent, 6)
    parent: wp.array(dtype=wp.int32),  # (C_child,) each child's parent cluster
    child_centres: wp.array2d(dtype=wp.float64),  # (C_child, 3) m
    parent_centres: wp.array2d(dtype=wp.float64),  # (C_parent, 3) m
    nodes: wp.array2d(dtype=wp.float64),  # (nu_parent * nv_parent, 3) m: the parent grid's points
    nv_child: int,
    p: int,
    iv: wp.array(dtype=wp.int32),  # (nv_parent,) first child v-node of each parent v-node
    wv: wp.array2d(dtype=wp.float64),  # (nv_parent, p)
    k: wp.float64,
    table: wp.array(dtype=wp.vec2d),
    half: wp.array3d(dtype=wp.float64),  # (C_child, nu_parent * nv_child, 6), zeroed
    offset: int,
):
    """The transpose of the forward's v-interpolation and re-phasing, for one parent u-row of
    one child per thread: the parent's weights times exp(+j k (|P - c_parent| - |P - c_child|))
    at each parent node P of the row, spread along v onto the child's v-nodes. The thread owns
    the output row (child, u-row), so its scattered adds are race-free and in a fixed order."""
    t = wp.tid() + offset
    nu = nodes.shape[0] // iv.shape[0]
    nv = iv.shape[0]
    c = t // nu
    i = t - c * nu
    qp = parent[c]
    cp = wp.vec3d(parent_centres[qp, 0], parent_centres[qp, 1], parent_centres[qp, 2])
    cc = wp.vec3d(child_centres[c, 0], child_centres[c, 1], child_centres[c, 2])
    base = i * nv_child
    for j in range(nv):
        node = i * nv + j
        P = wp.vec3d(nodes[node, 0], nodes[node, 1], nodes[node, 2])
        ep = cis(k * wp.length(P - cp), table)
        ec = cis(k * wp.length(P - cc), table)
        # exp(j k (r_p - r_c)) = ep * conj(ec), the forward's re-phasing factor (a transpose,
        # not an adjoint: no conjugation)
        pr = ep[0] * ec[0] + ep[1] * ec[1]
        pi = ep[1] * ec[0] - ep[0] * ec[1]
        x = vec6d()
        for q in range(3):
            br = beta[qp, node, q]
            bi = beta[qp, node, q + 3]
            x[q] = pr * br - pi * bi
            x[q + 3] = pr * bi + pi * br
        for b in range(p):
            w = wv[j, b]
            dst = base + iv[j] + b
            for q in range(6):
                half[c, dst, q] = half[c, dst, q] + w * x[q]


@wp.kernel
def anterpolate_u(
    half: wp.array3d(dtype=wp.float64),  # (C, nu_parent * nv_child, 6) from rephase_anterpolate_v
    nv: int,
    indptr: wp.array(dtype=wp.int32),  # (nu_child + 1,) CSR over the child's u-nodes
    rows: wp.array(dtype=wp.int32),  # (nnz,) the parent u-nodes whose stencil covers the node
    lagrange: wp.array(dtype=wp.float64),  # (nnz,) their weights
    out: wp.array3d(dtype=wp.float64),  # (C, nu_child * nv_child, 6)
    offset: int,
):
    """The transpose of the forward's u-interpolation: one thread per (child, child node)."""
    t = wp.tid() + offset
    nu = indptr.shape[0] - 1
    n_nodes = nu * nv
    c = t // n_nodes
    node = t - c * n_nodes
    a = node // nv
    j = node - a * nv
    acc = vec6d()
    for e in range(indptr[a], indptr[a + 1]):
        w = lagrange[e]
        src = rows[e] * nv + j
        for q in range(6):
            acc[q] = acc[q] + w * half[c, src, q]
    for q in range(6):
        out[c, node, q] = acc[q]


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
