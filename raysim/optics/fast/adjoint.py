"""The fast radiator's transposed sum: the adjoint (VJP) of a radiation sum, multilevel.

The forward multilevel sum (:mod:`raysim.optics.fast.multilevel`) is a linear map
E = T A_{stop+1} ... A_leaf L x of the elements' values x (reflector frame, m; raw sums before
the kind's prefactor). The Jacobians' VJPs need, per element j, out_j = sum_t K_j(P_t) b_t for
complex weights b_t (3,) on the targets P_t, where K_j(P) carries the Green phase
exp(-j k |P - s_j|) as the forward pair does (:func:`raysim.optics.kernels.radiation.adjoint_kernel`;
out_j is linear in b, no conjugation). By reciprocity this is the plain transpose of the same
chain, run from the targets down to the elements on the same plan:

1. stop level, the transpose of the last step: each cluster's weights exp(-j k |P_t - c|) b_t
   taken back to its Fourier coefficients (on a tensor grid of targets, the same two matrix
   products transposed; elsewhere, the Lagrange weights scattered onto the refined grid and the
   refinement transposed), then to its grid by the (symmetric) DFT;
2. down the tree: each child's weights are its parent's, times
   exp(+j k (|P - c_parent| - |P - c_child|)), taken back to the child's grid by the transpose
   of the zero-padding refinement (:func:`raysim.optics.fast.chart.restrict`);
3. leaves: the mirrored rows folded back onto the rows theta <= pi, the leaf centre's phase
   exp(+j k |P_n - c_leaf|) put back, and out_j = sum_n K_j(P_n) beta_leaf(n) over the leaf's
   own nodes P_n (a segmented adjoint kernel, a thread per element).

Same plan as the forward JVP's (:func:`raysim.optics.fast.radiator.plan_for` for the kind the
JVP sums: both weigh their leaves alike), so the gradients agree
with the direct transposed sum to about the forward's tolerance. Every step is a matrix
product, an FFT, a sparse product or a thread-owned row in a fixed order: the same bits on
every run.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.fft as sfft
from numpy.typing import ArrayLike, NDArray
from scipy import sparse

from raysim.errors import RaysimError
from raysim.optics import runtime
from raysim.optics.fast import multilevel
from raysim.optics.fast.chart import (
    FFT_WORKERS,
    Domain,
    domain_of,
    fold,
    grid_points,
    half_rows,
    lagrange,
    restrict,
    tensor_index,
    to_angles,
)
from raysim.optics.fast.multilevel import warray
from raysim.optics.fast.radiator import DEFAULT_TOL, describe, plan_for, tol_problem
from raysim.optics.fast.scratch import Scratch

#: bytes of weights held at once per step (clusters taken in chunks)
CHUNK_BYTES = 2.5e8


def _spectrum_to_grid(S_adj: NDArray[np.complex128], n: int) -> NDArray[np.complex128]:
    """The transpose of "grid -> its kept Fourier coefficients" (fft2 / n^2, the Nyquist row and
    column dropped): coefficients (c, n - 1, n - 1, 3) -> grid weights (c, n, n, 3). The DFT
    matrix is symmetric, so the transpose is the same DFT of the zero-filled coefficients."""
    keep = np.r_[0:n // 2, n - n // 2 + 1:n]
    full = np.zeros((S_adj.shape[0], n, n, 3), dtype=np.complex128)
    full[:, keep[:, None], keep[None, :]] = S_adj
    return sfft.fft2(full, axes=(1, 2), workers=FFT_WORKERS, overwrite_x=True) / (n * n)


def _tensor_weights(B: NDArray[np.complex128], the_plan: multilevel.Plan, domain: Domain,
                    k: float) -> Callable[[int, int], NDArray[np.complex128]]:
    """Step 1 on the domain's tensor grid, ``B`` (R * Q, 3) the weights on the whole grid: the
    transpose of :func:`raysim.optics.fast.multilevel.grid_sums`, as a function of a range of
    stop clusters q0 .. q1 - 1 (the series' basis and the grid's points made once)."""
    level = the_plan.levels[the_plan.stop]
    n = the_plan.sizes[the_plan.stop]
    keep, E_theta, E_phi_T = multilevel.series_basis(n, domain)
    E_theta_T, E_phi = np.ascontiguousarray(E_theta.T), np.ascontiguousarray(E_phi_T.T)  # (nk, R), (Q, nk)
    R, Q = E_theta.shape[0], E_phi_T.shape[1]
    points = multilevel.tensor_points(domain)
    nk = len(keep)
    per = max(1, int(CHUNK_BYTES // (16 * 3 * R * Q * 2)))

    def weights(q0: int, q1: int) -> NDArray[np.complex128]:
        out = np.empty((q1 - q0, n, n, 3), dtype=np.complex128)
        for c0 in range(q0, q1, per):
            c1 = min(c0 + per, q1)
            c = c1 - c0
            r = multilevel.distances(points, level.centres[c0:c1])
            X = (np.exp(-1j * k * r)[:, :, None] * B[None, :, :]).reshape(c, R, Q, 3)
            # (nk x R) X (R x Q) (Q x nk) per cluster and component, as two plain matrix products
            A = np.ascontiguousarray(np.transpose(X, (1, 0, 3, 2))).reshape(R, c * 3 * Q)
            W = (E_theta_T @ A).reshape(nk * c * 3, Q) @ E_phi  # (nk * c * 3, nk)
            S_adj = np.transpose(W.reshape(nk, c, 3, nk), (1, 0, 3, 2))  # (c, kθ, kφ, 3)
            out[c0 - q0:c1 - q0] = _spectrum_to_grid(S_adj, n)
        return out

    return weights


def _scatter_matrix(angles: NDArray[np.float64], the_plan: multilevel.Plan) -> sparse.csr_matrix:
    """(m * m, M): the transpose of the Lagrange interpolation from the refined periodic grid
    (m = oversampling x n) to the targets at ``angles`` (M, 2) rad."""
    n, p = the_plan.sizes[the_plan.stop], the_plan.p
    m = the_plan.oversampling * n
    axis = multilevel.target_axis(m, p)
    iu, wu = lagrange(angles[:, 0], axis, p)
    iv, wv = lagrange(angles[:, 1], axis, p)
    rows = np.mod(iu[:, None] - p + np.arange(p)[None, :], m)  # (M, p), wrapped
    cols = np.mod(iv[:, None] - p + np.arange(p)[None, :], m)
    M = len(angles)
    flat = (rows[:, :, None] * m + cols[:, None, :]).reshape(M, p * p)
    weights = (wu[:, :, None] * wv[:, None, :]).reshape(M, p * p)
    return sparse.csr_matrix((weights.ravel(), (flat.ravel(), np.repeat(np.arange(M), p * p))),
                             shape=(m * m, M))  # duplicates summed in a fixed order


def _scattered_weights(b: NDArray[np.complex128], angles: NDArray[np.float64], points: NDArray[np.float64],
                       the_plan: multilevel.Plan, k: float) -> Callable[[int, int], NDArray[np.complex128]]:
    """Step 1 for any targets: the transpose of
    :func:`raysim.optics.fast.multilevel.interpolated` (the Lagrange weights scattered onto the
    refined grid, :func:`_scatter_matrix`, made once; then the refinement transposed), as a
    function of a range of stop clusters q0 .. q1 - 1."""
    level = the_plan.levels[the_plan.stop]
    n = the_plan.sizes[the_plan.stop]
    m = the_plan.oversampling * n
    M = len(points)
    W_T = _scatter_matrix(angles, the_plan)
    per = max(1, int(CHUNK_BYTES // (48 * m * m * 2)))

    def weights(q0: int, q1: int) -> NDArray[np.complex128]:
        out = np.empty((q1 - q0, n, n, 3), dtype=np.complex128)
        for c0 in range(q0, q1, per):
            c1 = min(c0 + per, q1)
            r = multilevel.distances(points, level.centres[c0:c1])
            X = np.exp(-1j * k * r)[:, :, None] * b[None, :, :]  # (c, M, 3)
            fine = (W_T @ np.moveaxis(X, 1, 0).reshape(M, -1)).reshape(m, m, c1 - c0, 3)
            out[c0 - q0:c1 - q0] = restrict(np.moveaxis(fine, 2, 0), n)
        return out

    return weights


def disaggregate(beta: NDArray[np.complex128], child: int, the_plan: multilevel.Plan, domain: Domain,
                 k: float, device: str, q_lo: int = 0, q_hi: int | None = None,
                 scratch: Scratch | None = None) -> NDArray[np.complex128] | multilevel.LeafGrids:
    """The weights (C1, nc, nc, 3) of the children of parents q_lo .. q_hi - 1 (level
    ``child - 1``, whose weights ``beta`` holds in order), or, for leaves on grids of their own
    sizes, their weights on those grids (a :class:`~raysim.optics.fast.multilevel.LeafGrids`):
    step 2 (module docs), the transpose of :func:`raysim.optics.fast.multilevel.aggregate` (the
    re-phasing in a Warp kernel, the refinement's transpose by FFTs). ``scratch``: where the
    result (role ("level", child), or per size) and the re-phased grids are built, else new
    arrays."""
    wp = runtime.init()
    from raysim.optics.kernels import fast_adjoint, radiation

    low, up = the_plan.levels[child], the_plan.levels[child - 1]
    n, nc = the_plan.sizes[child - 1], the_plan.sizes[child]
    nodes = warray(grid_points(n, domain), device)
    table = warray(radiation.cis_table(), device, wp.vec2d)
    q_hi = len(up.keys) if q_hi is None else q_hi
    a, b = the_plan.children(child - 1, q_lo, q_hi)
    weights = warray(np.ascontiguousarray(beta).view(np.float64).reshape(-1, 6), device)
    parent_centres = warray(up.centres[q_lo:q_hi], device)
    classes = the_plan.leaf_classes(a, b) if child == the_plan.leaf else [(nc, np.arange(b - a))]
    own = len(classes) > 1  # leaves of several sizes (one class: every child, in order)
    outs = []
    for size, members in classes:
        shape = (len(members), size, size, 3)
        role = ("level", child, size) if own else ("level", child)
        outs.append(np.empty(shape, dtype=np.complex128) if scratch is None else scratch.array(role, shape))
    per = max(1, int(CHUNK_BYTES // (48 * n * n * 2)))
    for c0 in range(a, b, per):
        c1 = min(c0 + per, b)
        grids = (c1 - c0, n, n, 3)
        host = np.empty(grids, dtype=np.complex128) if scratch is None else scratch.array("shifted", grids)
        flat = host.reshape(-1, 3).view(np.float64)  # ((c1 - c0) n^2, 6)
        shifted = (warray(flat, device) if device == "cpu"
                   else wp.empty(flat.shape, dtype=wp.float64, device=device))
        runtime.launch(fast_adjoint.rephase_split, (c1 - c0) * n * n, [
            weights, n * n, warray((low.parent[c0:c1] - q_lo).astype(np.int32), device, wp.int32),
            warray(low.centres[c0:c1], device), parent_centres, nodes, k, table, shifted], device,
            min_chunk=256)
        if device != "cpu":
            flat[...] = shifted.numpy()
        if not own:  # the one class's size: a chunk's leaves may all be narrower than the level's widest
            outs[0][c0 - a:c1 - a] = restrict(host, classes[0][0], overwrite=True)
            continue
        for (size, members), out in zip(classes, outs, strict=True):
            i0, i1 = np.searchsorted(members, (c0 - a, c1 - a))
            if i1 > i0:
                out[i0:i1] = restrict(host[members[i0:i1] - (c0 - a)], size, overwrite=True)
    if not own:
        return outs[0]
    return multilevel.LeafGrids([(size, members, out)
                                 for (size, members), out in zip(classes, outs, strict=True)])


def leaf_sums(kernel: Any, src: NDArray[np.float64], beta: NDArray[np.complex128] | multilevel.LeafGrids,
              the_plan: multilevel.Plan, domain: Domain, k: float, device: str, lo: int = 0,
              hi: int | None = None) -> NDArray[np.float64]:
    """Step 3 (module docs) for leaves lo .. hi - 1 (their weights ``beta``, on the leaf
    level's grid or on grids of their own sizes): (8, m) for their elements, in leaf order
    (``src`` holds every element in leaf order). ``kernel``: from
    :func:`raysim.optics.kernels.radiation.segment_adjoint_kernel`."""
    full = the_plan.levels[the_plan.leaf]
    hi = len(full.keys) if hi is None else hi
    e0, e1 = int(full.begins[lo]), int(full.ends[hi - 1])
    if not isinstance(beta, multilevel.LeafGrids):
        leaves = np.arange(lo, hi)
        return _class_sums(kernel, src[:, e0:e1], beta, leaves, the_plan, domain, k, device)
    out = np.empty((8, e1 - e0))
    for _, members, weights in beta.classes:
        leaves = lo + members
        counts = full.ends[leaves] - full.begins[leaves]
        # the class's elements: each leaf's range, one after another
        starts = np.repeat(full.begins[leaves] - np.cumsum(counts) + counts, counts)
        columns = starts + np.arange(int(counts.sum()))
        out[:, columns - e0] = _class_sums(kernel, src[:, columns], weights, leaves, the_plan, domain, k,
                                           device)
    return out


def _class_sums(kernel: Any, src: NDArray[np.float64], beta: NDArray[np.complex128],
                leaves: NDArray[np.int64], the_plan: multilevel.Plan, domain: Domain, k: float,
                device: str) -> NDArray[np.float64]:
    """Step 3 for the ``leaves`` (indices, ascending) whose weights ``beta`` (C, n, n, 3) are on
    one n x n grid; ``src`` their elements (leaf by leaf): (8, len) for those elements."""
    wp = runtime.init()
    from raysim.optics.kernels import fast_adjoint, radiation

    full = the_plan.levels[the_plan.leaf]
    C, n = len(leaves), beta.shape[1]
    nodes = grid_points(n, domain, half_rows(n))
    # the leaf kernel takes the nodes four at a time (vector lanes): pad them to a multiple of
    # four with copies of the last node and zero weights, which add exactly nothing
    n_half = len(nodes)
    n_nodes = -(-n_half // 4) * 4
    nodes = np.vstack([nodes, np.repeat(nodes[-1:], n_nodes - n_half, axis=0)])
    half = fold(beta, n).reshape(C, n_half, 3)
    split = np.zeros((C, n_nodes, 6))  # Re 3, Im 3
    split[:, :n_half, :3] = half.real
    split[:, :n_half, 3:] = half.imag
    table = warray(radiation.cis_table(), device, wp.vec2d)
    # the leaf centre's phase put back once per (leaf, node), not once per element
    weights = wp.empty((C, n_nodes, 6), dtype=wp.float64, device=device)
    runtime.launch(fast_adjoint.phase_rows, C * n_nodes, [
        warray(nodes, device), warray(split, device), warray(full.centres[leaves], device), 1.0, k, table,
        weights], device, min_chunk=1024)
    leaf_of = np.repeat(np.arange(C), full.ends[leaves] - full.begins[leaves]).astype(np.int32)
    out = wp.zeros((8, src.shape[1]), dtype=wp.float64, device=device)
    runtime.launch(kernel, src.shape[1], [
        warray(nodes.T, device), warray(leaf_of, device, wp.int32), weights.reshape((-1, 6)), n_nodes,
        warray(src, device), k, 1.0 / k, table, out], device, min_chunk=16)
    return out.numpy()


def _descend(kernel: Any, ordered: NDArray[np.float64], beta: NDArray[np.complex128],
             the_plan: multilevel.Plan, domain: Domain, k: float, device: str, level: int, q0: int, q1: int,
             result: NDArray[np.float64], scratch: Scratch) -> None:
    """Steps 2 and 3 below clusters q0 .. q1 - 1 of ``level`` (their weights ``beta``): their
    elements' sums written into ``result`` (8, n) in leaf order; each level's weights built in
    ``scratch`` (read below before the level is asked for again)."""
    if level == the_plan.leaf:
        leaves = the_plan.levels[level]
        result[:, leaves.begins[q0]:leaves.ends[q1 - 1]] = leaf_sums(kernel, ordered, beta, the_plan, domain,
                                                                     k, device, q0, q1)
        return
    for p0, p1 in the_plan.chunks(level, q0, q1):
        part = disaggregate(beta[p0 - q0:p1 - q0], level + 1, the_plan, domain, k, device, p0, p1, scratch)
        _descend(kernel, ordered, part, the_plan, domain, k, device, level + 1,
                 *the_plan.children(level, p0, p1), result, scratch)


def transposed_sum(kernel: Any, src: ArrayLike, points: ArrayLike, b: ArrayLike, k: float,
                   centre: ArrayLike | None, device: str = "cpu", tol: float = DEFAULT_TOL,
                   force: bool = False, info: dict | None = None,
                   kind: str = "shift") -> NDArray[np.float64] | None:
    """The transposed sum (8, n_elements) by the multilevel plan, or None where the direct sum
    should run (as the forward's rules: targets not on one sphere about ``centre`` (m), no
    separated level, or an estimated cost above the direct sum's unless ``force``).

    ``kernel``: the kind's segmented adjoint kernel; ``src`` (rows, n) the elements in the
    kind's packed layout (positions in rows 0..2, m); ``points`` (M, 3) m; ``b`` (M, 3) complex
    weights on the targets; ``k`` rad/m. ``info``, when given, receives ``method`` (the plan or
    ``direct``) and ``seconds``. ``kind``: the forward kind whose JVP this transposes (``shift``
    for PO, ``fringe`` for PTD's rim): its plan is the forward's, so each sum is the exact
    transpose of the other.
    """
    if (problem := tol_problem(tol)) is not None:
        raise RaysimError(problem)
    start = time.perf_counter()
    src = np.ascontiguousarray(np.asarray(src, dtype=np.float64))
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    bw = np.asarray(b, dtype=np.complex128).reshape(-1, 3)
    dev = runtime.resolve_device(device)
    the_plan = None
    domain = domain_of(pts, centre) if centre is not None and len(pts) and src.shape[1] else None
    if domain is not None:
        the_plan = plan_for([src], domain, k, tol, kind=kind)
    if the_plan is None or (the_plan.cost >= the_plan.direct_cost and not force):
        if info is not None:
            info["method"] = "direct"
        return None
    assert domain is not None
    angles = to_angles(pts, domain.centre)
    index = tensor_index(angles, domain) if the_plan.oversampling == 0 else None
    if index is not None:
        B = np.zeros((len(np.asarray(domain.thetas)) * len(np.asarray(domain.phis)), 3), dtype=np.complex128)
        np.add.at(B, index, bw)  # a target twice on the grid counts twice
        weights = _tensor_weights(B, the_plan, domain, k)
    else:
        if the_plan.oversampling == 0:  # a tensor plan's stray target: the general last step
            the_plan = multilevel.general_last_step(the_plan)
        weights = _scattered_weights(bw, angles, pts, the_plan, k)
    ordered = multilevel.leaf_ordered([src], the_plan)
    result = np.empty((8, src.shape[1]))
    # a chunk of stop clusters at a time, down to the leaves a chunk of families per level at a
    # time (the forward's walk, :meth:`raysim.optics.fast.multilevel.Plan.chunks`)
    scratch = Scratch()
    for q0, q1 in the_plan.stop_chunks():
        _descend(kernel, ordered, weights(q0, q1), the_plan, domain, k, dev, the_plan.stop, q0, q1, result,
                 scratch)
    out = np.empty_like(result)
    out[:, the_plan.order] = result  # back from leaf order to the elements' order
    if info is not None:
        info["method"] = describe(the_plan)
        info["seconds"] = time.perf_counter() - start
    return out
