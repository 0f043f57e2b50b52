"""The wave model's exact Jacobian and the Gauss-Newton refinement built on it.

The Jacobian-vector product is checked against central finite differences of the full PO +
PTD engine (the refinement's own model, :class:`solver.forward.WaveForward`, called on the
perturbed grid) on the paper's dish (D = 110 m, F = 33 m, R = 10 m) at 0.1 and 0.3 GHz, on a
reduced sphere grid; the adjoint against the JVP by the identity <y, J v> = <J^T y, v>; the
grid-to-surface map against the model's own spline; the moved rim frame against the edge
quadrature of the moved surface. Gauss-Newton runs on a small dish of the paper's shape with
data made by a finer quadrature than its model.
"""

import itertools
import sys

import numpy as np
import pytest

from raysim.cli import main
from raysim.maps.fieldmap import fieldmap, save
from raysim.maps.sphere import SphereGrid
from raysim.optics import po, ptd_jacobian
from raysim.surface.deformation import GaussianBumps, PaperDeformation
from raysim.surface.edges import edge_quadrature
from raysim.surface.gridded import GriddedMap
from raysim.surface.mesh import paraboloid
from solver.aperture import ApertureGrid
from solver.errors import SolverError
from solver.forward import GOEdgeForward, GOForward, WaveForward, distributed
from solver.gauss_newton import GaussNewtonOptions, choose_method
from solver.invert import InvertOptions, invert
from solver.jacobian import GridToSamples, WaveJacobian
from solver.nonlinear import extend_outside

D, F, R = 110.0, 33.0, 10.0
# one bump inside, two reaching the rim (where the PTD fringe field answers too)
PERTURBATION = GaussianBumps(((12.0, 6.0, 1e-4, 7.0), (50.0, 12.0, -8e-5, 5.0),
                              (-38.0, -36.0, 6e-5, 6.0)))


@pytest.mark.slow
@pytest.mark.parametrize("frequency_hz", [0.1e9, 0.3e9])
def test_jvp_matches_finite_differences_of_the_po_ptd_engine(frequency_hz):
    grid = ApertureGrid(D, 64)
    X, Y = grid.XY
    state = grid.masked(PaperDeformation(D, F)(X, Y))
    model = WaveForward(frequency_hz, ptd=True)
    sphere = SphereGrid(R, 6, 8)
    jac = WaveJacobian(model, sphere, F, D, grid, state)
    v = PERTURBATION(X, Y)[grid.mask]
    dI = jac.jvp(v)

    def intensity(step):
        d = state.copy()
        d[grid.mask] += step * v
        return model(sphere, F, D, grid.x, grid.y, extend_outside(grid, d))

    h = 1e-2  # 1 um at the largest bump: the quadratic term is far below 1e-4
    fd = (intensity(h) - intensity(-h)) / (2 * h)
    assert np.linalg.norm(dI - fd) / np.linalg.norm(fd) < 1e-4
    # without the PTD part of the derivative the rim bumps miss by far more than that
    rim_only = jac.field_jvp(v) - _po_only_field_jvp(jac, v)
    miss = 2 * np.real(np.sum(np.conj(jac.E) * rim_only, axis=-1)).reshape(fd.shape)
    assert np.linalg.norm(miss) / np.linalg.norm(fd) > 1e-3


def _po_only_field_jvp(jac, v):
    from raysim.optics import po_jacobian

    dz, hx, hy = jac.samples.apply(v)
    return po_jacobian.jvp(jac.elements, jac.points, dz, hx, hy)


def _paper_jacobian(n_theta, n_phi, seed):
    """The PO + PTD Jacobian at 0.1 GHz about the Eq. 8 surface (N = 48, a small sphere grid),
    a random surface vector v and a random sample vector y."""
    grid = ApertureGrid(D, 48)
    X, Y = grid.XY
    jac = WaveJacobian(WaveForward(0.1e9, ptd=True), SphereGrid(R, n_theta, n_phi), F, D, grid,
                       grid.masked(PaperDeformation(D, F)(X, Y)))
    rng = np.random.default_rng(seed)
    return jac, rng.standard_normal(int(grid.mask.sum())), rng.standard_normal((n_theta, n_phi))


def test_the_jacobian_refuses_a_reflector_memory_cannot_hold(monkeypatch):
    """The forward sum holds a batch of samples, the Jacobian all of them: on a machine whose
    memory holds the forward model's run of the paper's dish at 0.1 GHz but not 400 bytes a
    sample more, the Jacobian refuses in one line before the model's field is computed."""
    import raysim.simulate as sim
    from raysim.surface.quadrature import plan

    n = plan(paraboloid(D, F, 5.0), 299_792_458.0 / 0.1e9, po.DEFAULT_SAMPLES_PER_WAVELENGTH).n_samples
    monkeypatch.setattr(sim, "physical_memory", lambda: sim.WAVE_BASE_BYTES + 400.0 * n)
    sim.check_wave_size("po+ptd", D, 0.1e9)  # the forward model fits

    def no_field(*args, **kwargs):
        raise AssertionError("the model's field was computed before the refusal")

    monkeypatch.setattr(WaveForward, "field", no_field)
    grid = ApertureGrid(D, 48)
    with pytest.raises(SolverError, match="Gauss-Newton's Jacobian needs .* more than this machine's"):
        WaveJacobian(WaveForward(0.1e9, ptd=True), SphereGrid(R, 5, 6), F, D, grid, np.zeros(grid.mask.shape))


def test_vjp_is_the_transpose_of_the_jvp():
    jac, v, y = _paper_jacobian(5, 6, seed=3)
    lhs, rhs = float(np.sum(y * jac.jvp(v))), float(jac.vjp(y) @ v)
    assert abs(lhs - rhs) <= 1e-9 * abs(lhs)


def test_jacobian_on_a_subset_of_cells_is_those_rows_of_the_whole():
    # a coarse Gauss-Newton step radiates to some cells only; the products must be the full
    # Jacobian's rows there (its field computed at all cells in one radiation)
    jac, v, y = _paper_jacobian(6, 8, seed=5)
    cells = np.zeros((6, 8), dtype=bool)
    cells[::2, ::4] = True
    whole_jvp, whole_vjp = jac.jvp(v), jac.vjp(np.where(cells, y, 0.0))
    jac.restrict(cells)
    part_jvp, part_vjp = jac.jvp(v), jac.vjp(y)
    assert np.all(part_jvp[~cells] == 0.0)
    assert np.linalg.norm(part_jvp - np.where(cells, whole_jvp, 0.0)) <= \
        1e-12 * np.linalg.norm(whole_jvp[cells])
    assert np.linalg.norm(part_vjp - whole_vjp) <= 1e-12 * np.linalg.norm(whole_vjp)
    assert np.linalg.norm(whole_jvp[~cells]) > 0.1 * np.linalg.norm(whole_jvp)


def test_grid_map_is_the_models_spline_and_its_transpose():
    grid = ApertureGrid(D, 40)
    rng = np.random.default_rng(0)
    r = 0.5 * D * np.sqrt(rng.random(3000))
    r[:200] = 0.5 * D  # on the rim: beyond the outer grid centres, clamped like FITPACK
    phi = 2 * np.pi * rng.random(3000)
    x, y = r * np.cos(phi), r * np.sin(phi)
    values = rng.standard_normal(int(grid.mask.sum()))
    delta = np.full((grid.N, grid.N), np.nan)
    delta[grid.mask] = values
    spline = GriddedMap(grid.x, grid.y, extend_outside(grid, delta))
    samples = GridToSamples(grid, x, y)
    dz, hx, hy = samples.apply(values)
    gx, gy = spline.gradient(x, y)
    np.testing.assert_allclose(dz, spline(x, y), atol=1e-12)
    np.testing.assert_allclose(hx, gx, atol=1e-12)
    np.testing.assert_allclose(hy, gy, atol=1e-12)
    a, b, c = rng.standard_normal((3, 3000))
    u = rng.standard_normal(values.size)
    dz, hx, hy = samples.apply(u)
    assert samples.transpose(a, b, c) @ u == pytest.approx(a @ dz + b @ hx + c @ hy, rel=1e-12)


def test_moved_rim_frame_is_the_quadrature_of_the_moved_surface():
    dish = paraboloid(D, F, 5.0).deformed(PaperDeformation(D, F))
    wave = po.Illumination.plane_wave(0.3e9, (0, 0, -1), (1, 0, 0))
    state = ptd_jacobian.edge_state(dish, wave)
    bump = GaussianBumps(((54.0, 3.0, 2e-3, 4.0), (-30.0, 46.0, -1e-3, 6.0)))
    moved = edge_quadrature(dish.deformed(bump), wave.wavelength / 4.0, "rim")
    dz = bump(state.x, state.y)
    dhx, dhy = bump.gradient(state.x, state.y)
    rebuilt = ptd_jacobian.perturbed_edges(state, dz, dhx, dhy)
    for name in ("points", "tangent", "normal", "inward", "length"):
        np.testing.assert_allclose(getattr(rebuilt, name), getattr(moved, name), atol=1e-12)


# --- Gauss-Newton on a small dish of the paper's shape ------------------------------------
SD, SF, SR, SFREQ = 30.0, 9.0, 3.0, 0.3e9
TRUTH = GaussianBumps(((0.0, 0.0, 5e-4, 5.0), (6.0, -4.0, -3e-4, 3.0)))


@pytest.fixture(scope="module")
def small_field():
    """PO + PTD data of the bumps by a finer model (3 m faces, 3 samples per wavelength)."""
    from raysim.optics import ptd

    sphere = SphereGrid(SR, 30, 36)
    wave = po.Illumination.plane_wave(SFREQ, (0, 0, -1), (1, 0, 0))
    dish = paraboloid(SD, SF, 3.0)
    intensity = []
    for reflector in (dish, dish.deformed(TRUTH)):
        E = po.sphere_field(reflector, sphere, wave, 3.0).E
        E = E + ptd.sphere_edge_field(reflector, sphere, wave, "rim", 8.0).E
        intensity.append(np.sum(np.abs(E) ** 2, axis=-1))
    return fieldmap(sphere, intensity[1], intensity[0], focal_length=SF, diameter=SD,
                    frequency_hz=SFREQ, method="po+ptd", sampling="centre")


@pytest.mark.slow
def test_gauss_newton_fits_the_data_and_beats_defect_correction(small_field):
    lines = []
    options = GaussNewtonOptions(iterations=2, inner=6)
    defect = invert(small_field, N=64, truth=TRUTH, refine_method="defect")
    gn = invert(small_field, N=64, truth=TRUTH, refine_method="gauss-newton",
                gauss_newton=options, log=lines.append)
    a = gn.attrs
    assert a["gn_used"] and not defect.attrs["gn_used"]
    misfit = [float(v) for v in a["gn_misfit_rms"].split(",")]
    assert misfit[-1] < 0.7 * misfit[0]
    assert a["rrms"] < defect.attrs["rrms"]
    # the share of the data the map leaves unexplained is Gauss-Newton's, not the defect
    # correction's before it
    assert a["refine_misfit_share"] == pytest.approx(
        misfit[-1] / a["refine_data_fa_rms"], rel=1e-3)
    assert a["refine_misfit_share"] < defect.attrs["refine_misfit_share"]
    assert any("misfit" in line and " s" in line for line in lines)
    # the data are absolute (scale 1); the recorded gain is the power balance's scale times
    # the factor Gauss-Newton ended with, not the defect correction's last one
    assert abs(a["gain"] - 1.0) < 1e-4
    defect_factor = float(defect.attrs["refine_gain_factor"].split(",")[-1])  # 9 decimals
    assert a["gain"] / defect.attrs["gain"] == pytest.approx(a["gn_gain_factor"] / defect_factor,
                                                             abs=2e-9)


@pytest.mark.slow
def test_coarse_steps_prepare_the_full_step(small_field):
    # coarse steps solve on one cell in eight; the last step, on all cells, then starts nearer
    # the answer: after the same number of full-cell LSQR iterations the surface is closer to
    # the truth than with the full step alone, and each coarse step lowers the all-cell misfit
    full = invert(small_field, N=64, truth=TRUTH, refine_method="gauss-newton",
                  gauss_newton=GaussNewtonOptions(iterations=1, inner=6))
    coarse = invert(small_field, N=64, truth=TRUTH, refine_method="gauss-newton",
                    gauss_newton=GaussNewtonOptions(iterations=3, inner=6, coarse=2))
    a = coarse.attrs
    assert a["gn_coarse_steps"] == 2 and "2 coarse" in a["gn_method"]
    misfit = [float(v) for v in a["gn_misfit_rms"].split(",")]
    assert len(misfit) == 4 and all(b < m for m, b in itertools.pairwise(misfit))
    assert a["rrms"] < full.attrs["rrms"]


def test_method_choice_refuses_what_the_jacobian_does_not_model(small_field):
    from solver.invert import Scan

    scan = Scan.from_fieldmap(small_field)
    paper = type("PaperScan", (), {"sphere": SphereGrid(R, 90, 360), "F": F, "D": D})
    # auto by what the steps cost: on the paper's grid 0.1 GHz affords the default 3 steps of
    # 60 LSQR iterations, 0.3 GHz fewer (its radiation costs five times more), spent in fewer,
    # longer steps, 0.6 GHz one step of at least 20; 2 GHz too few
    at_01, at_03, at_06 = (choose_method("auto", WaveForward(f), paper, 3) for f in (0.1e9, 0.3e9, 0.6e9))
    defaults = GaussNewtonOptions()
    assert at_01.method == "gauss-newton"
    assert (at_01.steps, at_01.inner) == (defaults.iterations, defaults.inner)
    assert at_03.method == "gauss-newton" and at_03.steps < defaults.iterations
    assert 60 <= at_03.steps * at_03.inner < defaults.iterations * defaults.inner
    assert at_03.inner <= defaults.inner
    assert at_06.method == "gauss-newton" and at_06.steps == 1 and 20 <= at_06.inner < 60
    # the choice keeps a last step on all cells when coarse steps are asked for
    applied = at_03.applied(GaussNewtonOptions(iterations=4, inner=60, coarse=3))
    assert (applied.iterations, applied.inner, applied.coarse) == (at_03.steps, at_03.inner,
                                                                   at_03.steps - 1)
    assert choose_method("auto", WaveForward(2e9), paper, 3).method == "defect"
    assert choose_method("gauss-newton", WaveForward(0.3e9), scan, 0).method == "defect"
    # the Jacobian is PO's (+ PTD's): the go+edge model (a WaveForward with other physics) and
    # GO are refused on request and skipped by auto
    for model in (GOEdgeForward(0.1e9, ptd=True), GOForward()):
        with pytest.raises(SolverError, match="needs the po or po\\+ptd model"):
            choose_method("gauss-newton", model, scan, 3)
        choice = choose_method("auto", model, scan, 3)
        assert choice.method == "defect" and model.name in choice.why
    # the Jacobian runs in this process: not on a Dask runner
    with distributed(object()):
        with pytest.raises(SolverError, match="not in blocks on Dask"):
            choose_method("gauss-newton", WaveForward(0.1e9), scan, 3)
        assert choose_method("auto", WaveForward(0.1e9), scan, 3).method == "defect"
    with pytest.raises(SolverError, match="unknown refine method"):
        InvertOptions(refine_method="newton")


def test_invert_refuses_gauss_newton_on_go_edge_before_any_work(small_field, monkeypatch):
    def no_field(*args, **kwargs):
        raise AssertionError("a model field was computed before the refusal")

    monkeypatch.setattr(GOEdgeForward, "_field", no_field)
    with pytest.raises(SolverError, match="model is 'go\\+edge'"):
        invert(small_field, N=32, model="go+edge", refine_method="gauss-newton")


@pytest.mark.parametrize("extra, message", [
    (["--refine-method", "newton"], "unknown refine method 'newton'"),
    (["--refine-method", "gauss-newton", "--workers", "2"], "not in blocks on Dask"),
    (["--refine-method", "gauss-newton", "--gn-steps", "2", "--gn-coarse", "2"],
     "must leave at least one step on all cells"),
])
def test_cli_refuses_in_one_line(monkeypatch, capsys, tmp_path, small_field, extra, message):
    path = save(small_field, tmp_path / "f.nc")
    monkeypatch.setattr(sys, "argv", ["raysim", "invert", str(path), "-o", str(tmp_path / "s.nc"),
                                      *extra])
    with pytest.raises(SystemExit) as exit_info:
        main()
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and message in err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "s.nc").exists()


def test_cli_steps_and_lsqr_iterations_reach_the_refinement(monkeypatch, tmp_path, small_field):
    import xarray as xr

    path = save(small_field, tmp_path / "f.nc")
    out = tmp_path / "s.nc"
    monkeypatch.setattr(sys, "argv", ["raysim", "invert", str(path), "-o", str(out), "--grid",
                                      "32", "--refine", "1", "--refine-method", "gauss-newton",
                                      "--gn-steps", "1", "--gn-lsqr", "2"])
    with pytest.raises(SystemExit) as exit_info:
        main()
    assert exit_info.value.code in (0, None)
    with xr.open_dataset(out) as surface:
        a = dict(surface.attrs)
    assert a["gn_used"] and int(a["gn_lsqr_iterations"]) <= 2
    assert len(a["gn_misfit_rms"].split(",")) <= 2   # the start and at most one step


def test_gauss_newton_options_refuse_out_of_range_settings():
    for bad in ({"iterations": 0}, {"inner": 0}, {"inner": 1001}, {"backtrack": -1},
                {"iterations": 2.5}, {"sigmas": -1.0}, {"coarse": -1},
                {"iterations": 3, "coarse": 3}):
        with pytest.raises(SolverError, match="Gauss-Newton"):
            GaussNewtonOptions(**bad)
