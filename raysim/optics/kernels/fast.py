"""Warp kernels of the fast radiator (:mod:`raysim.optics.fast`): the stop level to the targets.

Each target t sums, over the clusters c of the stop level, the p x p Lagrange interpolation of
the cluster's chart grid (phase of its centre taken out) times exp(-j k |P_t - c|). One thread
per target, clusters in a fixed order: a target's value never depends on the other targets.
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.f64 import F64_ONE
from raysim.optics.kernels.radiation import cis, vec6d

wp.set_module_options({"enable_backward": False})


@wp.kernel
def interpolate_targets(
    grids: wp.array3d(dtype=wp.float64),  # (C, nu * nv, 6): Re x, y, z, Im x, y, z
    nv: int,
    p: int,
    iu: wp.array(dtype=wp.int32),
    iv: wp.array(dtype=wp.int32),
    wu: wp.array2d(dtype=wp.float64),  # (M, p)
    wv: wp.array2d(dtype=wp.float64),
    centres: wp.array2d(dtype=wp.float64),  # (C, 3) m
    points: wp.array2d(dtype=wp.float64),  # (M, 3) m
    k: wp.float64,
    table: wp.array(dtype=wp.vec2d),
    out: wp.array2d(dtype=wp.float64),  # (M, 6)
    offset: int,
):
    t = wp.tid() + offset
    P = wp.vec3d(points[t, 0], points[t, 1], points[t, 2])
    total = vec6d()
    for c in range(grids.shape[0]):
        acc = vec6d()
        for a in range(p):
            row = (iu[t] + a) * nv + iv[t]
            inner = vec6d()
            for b in range(p):
                w = wv[t, b]
                for q in range(6):
                    inner[q] = inner[q] + w * grids[c, row + b, q]
            acc += wu[t, a] * inner
        d = P - wp.vec3d(centres[c, 0], centres[c, 1], centres[c, 2])
        e = cis(k * wp.sqrt(wp.dot(d, d)), table)  # exp(-j k r) = e[0] - j e[1]
        total += vec6d(e[0] * acc[0] + e[1] * acc[3], e[0] * acc[1] + e[1] * acc[4],
                       e[0] * acc[2] + e[1] * acc[5], e[0] * acc[3] - e[1] * acc[0],
                       e[0] * acc[4] - e[1] * acc[1], e[0] * acc[5] - e[1] * acc[2])
    for q in range(6):
        out[t, q] = total[q] * F64_ONE


@wp.kernel
def interpolate_u(
    grids: wp.array3d(dtype=wp.float64),  # (C, nu_child * nv_child, 6) child grids
    nv: int,
    p: int,
    iu: wp.array(dtype=wp.int32),  # (nu_parent,) first child node of each parent u-node
    wu: wp.array2d(dtype=wp.float64),  # (nu_parent, p)
    out: wp.array3d(dtype=wp.float64),  # (C, nu_parent * nv_child, 6)
    offset: int,
):
    """Child grids interpolated along u to the parent's u-nodes (one thread per output row)."""
    t = wp.tid() + offset
    n_rows = iu.shape[0] * nv
    c = t // n_rows
    r = t - c * n_rows
    i = r // nv
    j = r - i * nv
    acc = vec6d()
    for a in range(p):
        w = wu[i, a]
        src = (iu[i] + a) * nv + j
        for q in range(6):
            acc[q] = acc[q] + w * grids[c, src, q]
    for q in range(6):
        out[c, r, q] = acc[q]


@wp.kernel
def interpolate_v_merge(
    half: wp.array3d(dtype=wp.float64),  # (C_child, nu_parent * nv_child, 6) from interpolate_u
    nv_child: int,
    p: int,
    iv: wp.array(dtype=wp.int32),  # (nv_parent,)
    wv: wp.array2d(dtype=wp.float64),  # (nv_parent, p)
    first: wp.array(dtype=wp.int32),  # (C_parent + 1,) children of parent q: first[q]..first[q+1]-1
    child_centres: wp.array2d(dtype=wp.float64),  # (C_child, 3) m
    parent_centres: wp.array2d(dtype=wp.float64),  # (C_parent, 3) m
    nodes: wp.array2d(dtype=wp.float64),  # (nu_parent * nv_parent, 3) m: the parent grid's points
    k: wp.float64,
    table: wp.array(dtype=wp.vec2d),
    out: wp.array3d(dtype=wp.float64),  # (C_parent, nu_parent * nv_parent, 6)
    offset: int,
):
    """The parent grids: each child's u-interpolated grid along v, re-phased by
    exp(+j k (|P - c_parent| - |P - c_child|)), summed over the children in order."""
    t = wp.tid() + offset
    n_nodes = nodes.shape[0]
    nv = iv.shape[0]
    qp = t // n_nodes
    node = t - qp * n_nodes
    i = node // nv
    j = node - i * nv
    P = wp.vec3d(nodes[node, 0], nodes[node, 1], nodes[node, 2])
    dp = P - wp.vec3d(parent_centres[qp, 0], parent_centres[qp, 1], parent_centres[qp, 2])
    ep = cis(k * wp.sqrt(wp.dot(dp, dp)), table)  # exp(+j k r_parent) = ep[0] + j ep[1]
    total = vec6d()
    for c in range(first[qp], first[qp + 1]):
        acc = vec6d()
        for b in range(p):
            w = wv[j, b]
            src = i * nv_child + iv[j] + b
            for q in range(6):
                acc[q] = acc[q] + w * half[c, src, q]
        dc = P - wp.vec3d(child_centres[c, 0], child_centres[c, 1], child_centres[c, 2])
        ec = cis(k * wp.sqrt(wp.dot(dc, dc)), table)
        # exp(j k (r_p - r_c)) = ep * conj(ec)
        pr = ep[0] * ec[0] + ep[1] * ec[1]
        pi = ep[1] * ec[0] - ep[0] * ec[1]
        total += vec6d(pr * acc[0] - pi * acc[3], pr * acc[1] - pi * acc[4], pr * acc[2] - pi * acc[5],
                       pr * acc[3] + pi * acc[0], pr * acc[4] + pi * acc[1], pr * acc[5] + pi * acc[2])
    for q in range(6):
        out[qp, node, q] = total[q]
