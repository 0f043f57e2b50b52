"""The fast radiator's transposed sum: the adjoint (VJP) of a radiation sum, multilevel.

The forward multilevel sum (:mod:`raysim.optics.fast.multilevel`) is a linear map
E = T A_{stop+1} ... A_leaf L x of the elements' values x (reflector frame, m; raw sums before
the kind's prefactor). The Jacobians' VJPs need, per element j, out_j = sum_t K_j(P_t) b_t for
complex weights b_t (3,) on the targets P_t, where K_j(P) carries the Green phase
exp(-j k |P - s_j|) as the forward pair does (:func:`raysim.optics.kernels.radiation.adjoint_kernel`;
out_j is linear in b, no conjugation). By reciprocity this is the plain transpose of the same
chain, run from the targets down to the elements on the same plan:

1. stop level: beta_c(n) = sum_t W(t, n) exp(-j k |P_t - c|) b_t, W the Lagrange weights that
   ``to_targets`` interpolates with (anterpolation);
2. down the tree: beta_child(n_c) = sum_{n_p} w(n_p -> n_c) exp(+j k (|P_np - c_p| - |P_np - c_c|))
   beta_parent(n_p): the parent re-phased per child, then the transposed v- and u-interpolation;
3. leaves: out_j = sum_n K_j(P_n) exp(+j k |P_n - c_leaf|) beta_leaf(n) over the leaf's own grid
   nodes P_n (a segmented adjoint kernel, thread per element).

The interpolation errors are the forward's (same plan, same (p, s) = choose_order(tol / 2)), so
the gradients agree with the direct transposed sum to about the forward's tolerance. Every step
is a gather or a thread-owned row: the same bits on every run.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse

from raysim.optics import runtime
from raysim.optics.fast import multilevel
from raysim.optics.fast.chart import Axis, choose_order, domain_of, lagrange, to_chart
from raysim.optics.fast.radiator import DEFAULT_TOL

#: bytes of phased target weights held at once by the stop step (clusters taken in chunks)
PHASED_BYTES = 2.5e8


def _arr(a: NDArray, device: str, dtype: Any = None) -> Any:
    wp = runtime.init()
    return wp.array(np.ascontiguousarray(a), dtype=dtype or wp.float64, device=device)


def _split(z: NDArray[np.complex128]) -> NDArray[np.float64]:
    """Complex (..., 3) as float64 (..., 6): Re x, y, z, Im x, y, z."""
    return np.ascontiguousarray(np.concatenate([z.real, z.imag], axis=-1))


def _transposed_csr(cols: NDArray[np.int64], w: NDArray[np.float64],
                    n: int) -> tuple[NDArray[np.int32], NDArray[np.int32], NDArray[np.float64]]:
    """The transpose, as CSR (indptr (n + 1,), rows, weights), of the interpolation matrix whose
    row r has the weights ``w[r]`` (q,) at the columns ``cols[r]`` (q,) of ``n``: for each
    column (a coarse node), the rows (targets or finer nodes) that read it, in ascending order."""
    m, q = w.shape
    rows = np.repeat(np.arange(m), q)
    csc = sparse.csr_matrix((w.ravel(), (rows, cols.ravel())), shape=(m, n)).tocsc()
    csc.sort_indices()  # rows ascending within each node: a fixed summation order
    return csc.indptr.astype(np.int32), csc.indices.astype(np.int32), csc.data.astype(np.float64)


def _stencil(first: NDArray[np.int64], p: int) -> NDArray[np.int64]:
    """The p node indices first .. first + p - 1 of each row (m, p)."""
    return first[:, None] + np.arange(p)[None, :]


def _phase(points: NDArray[np.float64], values: NDArray[np.float64], centres: NDArray[np.float64],
           sign: float, k: float, device: str) -> Any:
    """exp(sign j k |P_t - c|) values[c or 0, t] for every centre c (C, M, 6), a Warp array;
    ``values`` numpy or Warp (C or 1, M, 6)."""
    wp = runtime.init()
    from raysim.optics.kernels import fast_adjoint, radiation

    out = wp.empty((len(centres), len(points), 6), dtype=wp.float64, device=device)
    runtime.launch(fast_adjoint.phase_rows, len(centres) * len(points), [
        _arr(points, device), values if isinstance(values, wp.array) else _arr(values, device),
        _arr(centres, device), sign, k,
        _arr(radiation.cis_table(), device, wp.vec2d), out], device, min_chunk=1024)
    return out


def _stop_weights(b: NDArray[np.complex128], the_plan: multilevel.Plan, u: NDArray[np.float64],
                  points: NDArray[np.float64], k: float, p: int, device: str) -> Any:
    """beta of every stop cluster on the stop grid (C, nu * nv, 6), a Warp array: step 1
    (module docs)."""
    wp = runtime.init()
    from raysim.optics.kernels import fast_adjoint

    level = the_plan.levels[the_plan.stop]
    au, av = the_plan.axes[the_plan.stop]
    iu, wu = lagrange(u[:, 0], au, p)
    iv, wv = lagrange(u[:, 1], av, p)
    # the 2-D stencil of each target flattened: node (iu + a) * nv + iv + b, weight wu[a] wv[b]
    m = len(u)
    cols = (_stencil(iu, p)[:, :, None] * av.n + _stencil(iv, p)[:, None, :]).reshape(m, p * p)
    w2 = (wu[:, :, None] * wv[:, None, :]).reshape(m, p * p)
    n_nodes = au.n * av.n
    indptr, rows, weights = _transposed_csr(cols, w2, n_nodes)
    C = len(level.keys)
    out = wp.zeros((C, n_nodes, 6), dtype=wp.float64, device=device)
    csr = [_arr(indptr, device, wp.int32), _arr(rows, device, wp.int32), _arr(weights, device)]
    b6 = _arr(_split(b)[None], device)
    # the phased weights of a few clusters at a time: all of them at once would hold C x M
    # complex 3-vectors (over a gigabyte at 1 GHz on the paper's grid)
    step = max(1, int(PHASED_BYTES // (48 * max(m, 1))))
    for c0 in range(0, C, step):
        c1 = min(C, c0 + step)
        phased = _phase(points, b6, level.centres[c0:c1], -1.0, k, device)  # (c1 - c0, M, 6)
        runtime.launch(fast_adjoint.anterpolate_targets, (c1 - c0) * n_nodes, [phased, *csr, out[c0:c1]],
                       device, min_chunk=256)
    return out


def disaggregate(beta: Any, child: int, the_plan: multilevel.Plan, domain: Any, k: float, p: int,
                 device: str) -> Any:
    """The child level's weights (C1, nu * nv, 6) from the parent level's ``beta`` (C0, ..., 6),
    Warp arrays: the transpose of :func:`raysim.optics.fast.multilevel.aggregate` (step 2,
    module docs)."""
    wp = runtime.init()
    from raysim.optics.kernels import fast_adjoint, radiation

    low, up = the_plan.levels[child], the_plan.levels[child - 1]
    cu, cv = the_plan.axes[child]
    pu, pv = the_plan.axes[child - 1]
    iu, wu = lagrange(pu.nodes, cu, p)
    iv, wv = lagrange(pv.nodes, cv, p)
    C1 = len(low.keys)
    half = wp.zeros((C1, pu.n * cv.n, 6), dtype=wp.float64, device=device)
    runtime.launch(fast_adjoint.rephase_anterpolate_v, C1 * pu.n, [
        beta, _arr(low.parent.astype(np.int32), device, wp.int32),
        _arr(low.centres, device), _arr(up.centres, device),
        _arr(multilevel._grid_points((pu, pv), domain), device), cv.n, p,
        _arr(iv.astype(np.int32), device, wp.int32), _arr(wv, device), k,
        _arr(radiation.cis_table(), device, wp.vec2d), half], device, min_chunk=4)
    indptr, rows, weights = _transposed_csr(_stencil(iu, p), wu, cu.n)
    out = wp.zeros((C1, cu.n * cv.n, 6), dtype=wp.float64, device=device)
    runtime.launch(fast_adjoint.anterpolate_u, C1 * cu.n * cv.n, [
        half, cv.n, _arr(indptr, device, wp.int32), _arr(rows, device, wp.int32),
        _arr(weights, device), out], device, min_chunk=256)
    return out


def leaf_sums(kernel: Any, src: NDArray[np.float64], beta: Any, the_plan: multilevel.Plan,
              domain: Any, k: float, rows_out: int, device: str) -> NDArray[np.float64]:
    """Step 3 (module docs): (rows_out, n) per element, in the elements' own order.
    ``kernel``: from :func:`raysim.optics.kernels.radiation.segment_adjoint_kernel`."""
    wp = runtime.init()
    from raysim.optics.kernels import radiation

    level = the_plan.levels[the_plan.leaf]
    axes: tuple[Axis, Axis] = the_plan.axes[the_plan.leaf]
    nodes = multilevel._grid_points(axes, domain)
    n_nodes = len(nodes)
    # the leaf centre's phase put back once per (leaf, node), not once per element
    weights = _phase(nodes, beta, level.centres, 1.0, k, device)
    leaf_of = np.repeat(np.arange(len(level.keys)), level.ends - level.begins).astype(np.int32)
    n = src.shape[1]
    out = wp.zeros((8, n), dtype=wp.float64, device=device)
    runtime.launch(kernel, n, [
        _arr(nodes.T, device), _arr(leaf_of, device, wp.int32), weights.reshape((-1, 6)), n_nodes,
        _arr(src[:, the_plan.order], device), k, 1.0 / k,
        _arr(radiation.cis_table(), device, wp.vec2d), out], device, min_chunk=16)
    acc = out.numpy()[:rows_out]
    result = np.empty_like(acc)
    result[:, the_plan.order] = acc  # back from leaf order to the elements' order
    return result


def transposed_sum(kernel: Any, src: ArrayLike, points: ArrayLike, b: ArrayLike, k: float,
                   centre: ArrayLike | None, device: str = "cpu", tol: float = DEFAULT_TOL,
                   force: bool = False, info: dict | None = None) -> NDArray[np.float64] | None:
    """The transposed sum (8, n_elements) by the multilevel plan, or None where the direct sum
    should run (as the forward's rules: targets not on one sphere about ``centre`` (m), no
    separated level, or an estimated cost above the direct sum's unless ``force``).

    ``kernel``: the kind's segmented adjoint kernel; ``src`` (rows, n) the elements in the
    kind's packed layout (positions in rows 0..2, m); ``points`` (M, 3) m; ``b`` (M, 3) complex
    weights on the targets; ``k`` rad/m. ``info``, when given, receives ``method`` (the plan or
    ``direct``) and ``seconds``.
    """
    start = time.perf_counter()
    src = np.ascontiguousarray(np.asarray(src, dtype=np.float64))
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    bw = np.asarray(b, dtype=np.complex128).reshape(-1, 3)
    dev = runtime.resolve_device(device)
    the_plan = None
    p, s = choose_order(tol / 2.0)  # the forward's choice for the same tolerance
    domain = domain_of(pts, centre) if centre is not None and len(pts) and src.shape[1] else None
    if domain is not None:
        the_plan = multilevel.plan(np.ascontiguousarray(src[:3].T), domain, k, p, s)
    if the_plan is None or (the_plan.cost >= the_plan.direct_cost and not force):
        if info is not None:
            info["method"] = "direct"
        return None
    assert domain is not None
    u = to_chart(pts, domain.centre)[0]
    beta = _stop_weights(bw, the_plan, u, pts, k, p, dev)
    for child in range(the_plan.stop + 1, the_plan.leaf + 1):
        beta = disaggregate(beta, child, the_plan, domain, k, p, dev)
    out = leaf_sums(kernel, src, beta, the_plan, domain, k, 8, dev)
    if info is not None:
        info["method"] = f"fast (levels {the_plan.stop}..{the_plan.leaf}, p {p}, s {s:g})"
        info["seconds"] = time.perf_counter() - start
    return out
