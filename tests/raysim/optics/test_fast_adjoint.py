"""The fast radiator's transposed sum (the PO Jacobian's VJP) against the direct one (issue 31).

The scaled dish of test_fast_radiator.py (D 10 m, F 3.3 m, 1 GHz, about 33 wavelengths across,
PO samples at 1.5 a wavelength) and a 45 x 90 grid on a sphere of 1 m about the focus. There the
plan may stop at its leaf level (no aggregation); the first test makes the last step dear in the
plan's cost model so that the plan has a leaf and a stop level, and anterpolation to the stop
grids, one transposed aggregation step and the segmented leaf kernel all run. The reference is the direct
transposed sum (``po_jacobian.vjp`` with ``radiator="direct"``), an independent implementation.
"""

from __future__ import annotations

import numpy as np
import pytest

from raysim.errors import RaysimError
from raysim.maps.sphere import SphereGrid

D, F, R = 10.0, 3.3, 1.0
CENTRE = (0.0, 0.0, F)


@pytest.fixture(scope="module")
def elements():
    from raysim.optics import po_jacobian
    from raysim.optics.illumination import Illumination
    from raysim.surface.mesh import paraboloid

    wave = Illumination.plane_wave(1e9, (0, 0, -1), (1, 0, 0))
    return po_jacobian.surface_elements(paraboloid(D, F, 1.0), wave, 1.5, "cpu")


@pytest.fixture(scope="module")
def points() -> np.ndarray:
    return SphereGrid(R, 45, 90).points(F).reshape(-1, 3)


@pytest.fixture(scope="module")
def weights(points) -> np.ndarray:
    rng = np.random.default_rng(7)
    return rng.standard_normal((len(points), 3)) + 1j * rng.standard_normal((len(points), 3))


@pytest.fixture(scope="module")
def direct(elements, points, weights):
    from raysim.optics import po_jacobian

    return po_jacobian.vjp(elements, points, weights)


def _fast(elements, points, weights, tol: float = 1e-6, **kw):
    from raysim.optics import po_jacobian

    info: dict = {}
    grads = po_jacobian.vjp(elements, points, weights, radiator="fast", tol=tol, centre=CENTRE,
                            info=info, **{"force": True, **kw})
    return grads, info["method"]


def _rel_rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.sum((a - b) ** 2) / np.sum(b**2)))


def test_fast_vjp_matches_the_direct_vjp(elements, points, weights, direct, monkeypatch) -> None:
    from raysim.optics.fast import multilevel

    monkeypatch.setattr(multilevel, "COST_BLAS", 1.0)  # the last step dear: the plan aggregates
    grads, method = _fast(elements, points, weights)
    stop, leaf = (int(x) for x in method.split("levels ")[1].split(",")[0].split(".."))
    assert stop < leaf, method  # transposed aggregation steps ran
    for fast, ref in zip(grads, direct, strict=True):
        if np.any(ref):  # x-polarised on axis: the dh_y gradient is exactly zero
            assert _rel_rms(fast, ref) < 1e-6
        else:
            assert np.max(np.abs(fast)) <= 1e-12 * np.max(np.abs(direct[0]))


def test_fast_vjp_is_the_transpose_of_the_fast_jvp(elements, points) -> None:
    """<J v, w> = <v, J^T w> with both sides through the multilevel sum."""
    from raysim.optics import po_jacobian

    rng = np.random.default_rng(4)
    n = len(elements)
    dz, hx, hy = (rng.standard_normal(n) * 1e-3 for _ in range(3))
    jv = po_jacobian.jvp(elements, points, dz, hx, hy, radiator="fast", tol=1e-6, centre=CENTRE, force=True)
    w = rng.standard_normal((len(points), 3)) + 1j * rng.standard_normal((len(points), 3))
    (gz, gx, gy), method = _fast(elements, points, w)
    assert method.startswith("fast")
    lhs = float(np.real(np.sum(np.conj(w) * jv)))
    rhs = float(gz @ dz + gx @ hx + gy @ hy)
    assert abs(lhs - rhs) <= 1e-6 * abs(rhs)


@pytest.mark.parametrize("one_family", [False, True])
def test_leaves_on_grids_of_their_own_sizes_keep_the_transpose(elements, points, one_family,
                                                               monkeypatch) -> None:
    """Where the plan aggregates, each leaf sums on a grid sized for its own bandwidth (several
    sizes on this dish); the fast VJP is still the exact transpose of the fast JVP: <J v, w>
    = <v, J^T w> to rounding, not merely to the tolerance. Also walked one family at a time,
    where a family's leaves may all share a size below the level's widest."""
    from raysim.optics import po_jacobian
    from raysim.optics.fast import multilevel

    monkeypatch.setattr(multilevel, "COST_BLAS", 1.0)  # the last step dear: the plan aggregates
    if one_family:
        monkeypatch.setattr(multilevel, "GRID_BYTES", 1.0)  # one cluster a chunk at every level
    rng = np.random.default_rng(6)
    n = len(elements)
    dz, hx, hy = (rng.standard_normal(n) * 1e-3 for _ in range(3))
    jv = po_jacobian.jvp(elements, points, dz, hx, hy, radiator="fast", tol=1e-6, centre=CENTRE, force=True)
    w = rng.standard_normal((len(points), 3)) + 1j * rng.standard_normal((len(points), 3))
    (gz, gx, gy), method = _fast(elements, points, w)
    assert "(leaves " in method, method
    lhs = float(np.real(np.sum(np.conj(w) * jv)))
    rhs = float(gz @ dz + gx @ hx + gy @ hy)
    assert abs(lhs - rhs) <= 1e-11 * abs(rhs)


def test_error_shrinks_with_tolerance(elements, points, weights, direct) -> None:
    errors = [_rel_rms(_fast(elements, points, weights, tol)[0][0], direct[0]) for tol in (1e-2, 1e-4, 1e-7)]
    assert errors[0] < 1e-2 and errors[1] < 1e-4 and errors[2] < 1e-7
    assert errors[2] < errors[1] < errors[0]


def test_the_same_bits_on_every_run_and_chunks_agree(elements, points, weights, monkeypatch) -> None:
    """Two runs give the same bits; a run with the clusters' weights taken three at a time
    agrees to rounding (the matrix products' blocking may change the last bits)."""
    from raysim.optics.fast import adjoint

    first, _ = _fast(elements, points, weights, 1e-4)
    again, _ = _fast(elements, points, weights, 1e-4)
    monkeypatch.setattr(adjoint, "CHUNK_BYTES", 3 * 96 * len(points))  # three clusters a chunk
    chunked, _ = _fast(elements, points, weights, 1e-4)
    for a, b, c in zip(first, again, chunked, strict=True):
        assert np.array_equal(a, b)
        assert np.max(np.abs(c - a)) <= 1e-12 * np.max(np.abs(a))


@pytest.mark.parametrize("last", [(0, 0), (6, 10)])
def test_every_step_of_the_transposed_tree(elements, points, weights, direct, last, monkeypatch) -> None:
    """The transposed sum with the plan's stop two levels above the leaves, walked a few
    clusters at a time at every level (a chunk size of a few grids), by the tensor series or the
    general last step: within tolerance of the direct VJP."""
    from dataclasses import replace

    from raysim.optics.fast import adjoint, multilevel

    original = multilevel.plan

    def shaped(*args, **kw):
        made = original(*args, **kw)
        if made is None or made.leaf < 2:
            return made
        shaped = replace(made, stop=made.leaf - 2, oversampling=last[0], p=last[1])
        monkeypatch.setattr(multilevel, "GRID_BYTES", 3 * 48 * made.sizes[made.leaf - 2] ** 2)
        assert len(shaped.stop_chunks()) > 1
        return shaped

    monkeypatch.setattr(adjoint.multilevel, "plan", shaped)
    monkeypatch.setattr(multilevel, "CHUNK_BYTES", 2e5)
    grads, method = _fast(elements, points, weights)
    assert method.startswith("fast")
    for fast, ref in zip(grads, direct, strict=True):
        if np.any(ref):
            assert _rel_rms(fast, ref) < 1e-6


def test_the_grid_steps_transposes_are_exact() -> None:
    """<A x, y> = <x, A^T y> to rounding for the refinement (zero-padded spectrum) and the
    mirror of the rows theta > pi, on random complex grids: the adjoint's steps 2 and 3."""
    from raysim.optics.fast.chart import fold, mirror, resample, restrict

    rng = np.random.default_rng(8)

    def grid(*shape: int) -> np.ndarray:
        return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)

    n, m = 10, 24
    G, X = grid(2, n, n, 3), grid(2, m, m, 3)
    assert abs(np.sum(resample(G, m) * X) - np.sum(G * restrict(X, n))) < 1e-12 * np.sum(np.abs(G * restrict(X, n)))
    H, Y = grid(2, n // 2 + 1, n, 3), grid(2, n, n, 3)
    assert abs(np.sum(mirror(H, n) * Y) - np.sum(H * fold(Y, n))) < 1e-12 * np.sum(np.abs(H * fold(Y, n)))


def test_direct_where_the_rules_say_so(elements, points, weights, direct) -> None:
    """The default is the direct sum; points off one sphere, or a cost estimate above the
    direct sum's (a small grid, not forced), also take it, with the same bits."""
    from raysim.optics import po_jacobian

    info: dict = {}
    default = po_jacobian.vjp(elements, points, weights, info=info)
    assert info["method"] == "direct"
    assert all(np.array_equal(a, b) for a, b in zip(default, direct, strict=True))
    off = points[:200] * np.linspace(0.9, 1.1, 200)[:, None]
    grads, method = _fast(elements, off, weights[:200])
    assert method == "direct"
    ref = po_jacobian.vjp(elements, off, weights[:200])
    assert all(np.array_equal(a, b) for a, b in zip(grads, ref, strict=True))
    _, method = _fast(elements, points[:20], weights[:20], force=False)
    assert method == "direct"


def test_an_unknown_radiator_is_refused(elements, points, weights) -> None:
    from raysim.optics import po_jacobian

    with pytest.raises(RaysimError, match="unknown radiator"):
        po_jacobian.vjp(elements, points[:4], weights[:4], radiator="fmm", centre=CENTRE)


def test_fringe_vjp_through_the_fast_radiator(points) -> None:
    """The rim's PTD fringe VJP (six shifted copies of each edge element, central differences)
    by the transposed multilevel sum against the direct one."""
    from raysim.optics import ptd_jacobian
    from raysim.optics.illumination import Illumination
    from raysim.surface.mesh import paraboloid

    wave = Illumination.plane_wave(1e9, (0, 0, -1), (1, 0, 0))
    state = ptd_jacobian.edge_state(paraboloid(D, F, 1.0), wave)
    rng = np.random.default_rng(5)
    c = rng.standard_normal((len(points), 3)) + 1j * rng.standard_normal((len(points), 3))
    direct = ptd_jacobian.vjp(state, wave, points, c)
    info: dict = {}
    fast = ptd_jacobian.vjp(state, wave, points, c, radiator="fast", tol=1e-6, centre=CENTRE, force=True,
                            info=info)
    assert info["method"].startswith("fast")
    for a, b in zip(fast, direct, strict=True):
        assert _rel_rms(a, b) < 1e-6


def test_fringe_jvp_through_the_fast_radiator(points) -> None:
    """The rim's fringe JVP (central differences of two copies of the edge elements) with both
    copies summed on one multilevel tree, against the direct sum's; and its pairing with the
    fast fringe VJP, <J v, c> = <v, J^T c>."""
    from raysim.optics import ptd_jacobian
    from raysim.optics.illumination import Illumination
    from raysim.surface.mesh import paraboloid

    wave = Illumination.plane_wave(1e9, (0, 0, -1), (1, 0, 0))
    state = ptd_jacobian.edge_state(paraboloid(D, F, 1.0), wave)
    rng = np.random.default_rng(3)
    n = len(state.edges)
    v = [rng.standard_normal(n) * scale for scale in (1e-4, 1e-3, 1e-3)]
    fast_kw = {"radiator": "fast", "tol": 1e-6, "centre": CENTRE, "force": True}
    direct = ptd_jacobian.jvp(state, wave, points, *v)
    fast = ptd_jacobian.jvp(state, wave, points, *v, **fast_kw)
    assert np.linalg.norm(fast - direct) <= 1e-6 * np.linalg.norm(direct)
    c = rng.standard_normal((len(points), 3)) + 1j * rng.standard_normal((len(points), 3))
    grads = ptd_jacobian.vjp(state, wave, points, c, **fast_kw)
    lhs = float(np.real(np.sum(np.conj(c) * fast)))
    rhs = sum(float(g @ d) for g, d in zip(grads, v, strict=True))
    assert abs(lhs - rhs) <= 1e-6 * abs(lhs)


def test_fringe_jacobian_at_the_finest_tolerance(points) -> None:
    """A tolerance of 1e-11 is a radiator tolerance like any other; the fringe Jacobian's sums,
    held a hundred times finer, were refused ("must lie in [1e-12, 1), got 1e-13"). Finer than
    the fast sum's finest, they are the direct sum's; a tolerance that is none is refused
    naming it."""
    from raysim.optics import ptd_jacobian
    from raysim.optics.illumination import Illumination
    from raysim.surface.mesh import paraboloid

    wave = Illumination.plane_wave(1e9, (0, 0, -1), (1, 0, 0))
    state = ptd_jacobian.edge_state(paraboloid(D, F, 1.0), wave)
    c = np.ones((len(points), 3), dtype=np.complex128)
    direct = ptd_jacobian.vjp(state, wave, points, c)
    info: dict = {}
    fast = ptd_jacobian.vjp(state, wave, points, c, radiator="fast", tol=1e-11, centre=CENTRE, info=info)
    assert info["method"] == "direct"
    for a, b in zip(fast, direct, strict=True):
        assert _rel_rms(a, b) < 1e-11
    with pytest.raises(RaysimError, match="got 2.0"):
        ptd_jacobian.vjp(state, wave, points, c, radiator="fast", tol=2.0, centre=CENTRE)
