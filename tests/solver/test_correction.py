"""Actuator commands (solver.actuators, solver.correction): against an independent dense fit, the
shared corners, Ruze against the closed form, the Zernike fit against the terms that made a map,
and the command's files."""

import csv
import tomllib

import numpy as np
import pytest

from raysim.maps.aperture import ApertureGrid
from raysim.surface.panels import PanelLayout
from solver import surface
from solver.actuators import ActuatorError, build_layout, corners_layout, read_actuators, screws_layout
from solver.correction import correct, noll_to_nm, ruze, zernike_fit
from solver.correction_io import run_correct
from tests.reference_zernike import zernike_sum

D, A = 110.0, 55.0
LAYOUT = PanelLayout((0.0, 13.75, 27.5, 41.25, 55.0), (6, 12, 18, 24), 0.01)
GRID = ApertureGrid(D, 96)


def _rng_map(seed=1):
    """Astigmatism plus random smooth bumps (m) on the grid, NaN outside the aperture."""
    rng = np.random.default_rng(seed)
    X, Y = GRID.XY
    delta = 80e-6 * (X**2 - Y**2) / A**2
    for _ in range(12):
        x0, y0 = rng.uniform(-40, 40, 2)
        delta += rng.normal(0, 20e-6) * np.exp(-((X - x0) ** 2 + (Y - y0) ** 2) / (2 * 8.0**2))
    return GRID.masked(delta)


def _dense_reference(delta, layout, acts):
    """The dense fit's commands (see :func:`_dense_system`)."""
    M, target = _dense_system(delta, layout, acts)
    sol, *_ = np.linalg.lstsq(M, -target, rcond=None)
    return sol


def _joint_reference(delta, layout, acts):
    """The dense fit with piston and tilt free beside the commands: the commands of least norm
    that minimise ||M c + g t + delta|| over the panel points (the tilt columns x, y and the
    piston column projected out with numpy's lstsq; no code shared with solver.correction)."""
    M, target = _dense_system(delta, layout, acts)
    X, Y = GRID.XY
    on = GRID.mask & np.isfinite(delta) & (layout.panel_at(X, Y) >= 0)
    g = np.stack([np.ones(int(on.sum())), X[on], Y[on]], axis=1)  # row order of _dense_system

    def off_g(v):
        return v - g @ np.linalg.lstsq(g, v, rcond=None)[0]

    sol, *_ = np.linalg.lstsq(off_g(M), -off_g(target), rcond=None)
    return sol


def _dense_system(delta, layout, acts):
    """An independent dense fit: per panel, the shape through its support points built from the
    local-frame monomials by a Vandermonde solve, assembled point by point into a dense matrix
    and solved with numpy's lstsq (no code shared with solver.correction's sparse assembly)."""
    X, Y = GRID.XY
    ids = np.where(GRID.mask & np.isfinite(delta), layout.panel_at(X, Y), -1)
    rows, target = [], []
    for iy, ix in zip(*np.nonzero(ids >= 0), strict=True):
        p = ids[iy, ix]
        sup = acts.supports[p]
        phi_a, phi_b = layout.angular_limits(p)
        mid = 0.5 * (phi_a + phi_b)
        rot = np.array([[np.cos(mid), np.sin(mid)], [-np.sin(mid), np.cos(mid)]])
        c = layout.centres()[p]

        def mono(x, y, k, rot=rot, c=c):
            s, t = rot @ (np.array([x, y]) - c)
            return np.array([1, s, t, s * t, s * s, t * t][:k])

        k = len(sup)
        V = np.array([mono(sx, sy, k) for _, sx, sy in sup])
        w = mono(X[iy, ix], Y[iy, ix], k) @ np.linalg.inv(V)
        row = np.zeros(acts.n_actuators)
        for (a, _, _), wk in zip(sup, w, strict=True):
            row[a] += wk
        rows.append(row)
        target.append(delta[iy, ix])
    return np.array(rows), np.array(target)


@pytest.mark.parametrize("kind", ["corners", "screws"])
def test_commands_match_an_independent_dense_fit(kind):
    acts = corners_layout(LAYOUT) if kind == "corners" else screws_layout(LAYOUT)
    delta = _rng_map()
    result = correct(GRID, delta, LAYOUT, acts)
    reference = _dense_reference(result.before, LAYOUT, acts)
    scale = np.max(np.abs(reference))
    assert np.max(np.abs(result.commands - reference)) < 1e-9 * scale
    assert result.rms_after < 0.5 * result.rms_before


def test_shared_corner_moves_every_panel_it_holds():
    acts = corners_layout(LAYOUT)
    # corners where rings meet with matching cuts are held by four panels; the centre by six
    counts = [len(acts.panels_of(a)) for a in range(acts.n_actuators)]
    assert max(counts) == 6 and counts.count(4) > 0
    a = counts.index(4)
    one = np.zeros(acts.n_actuators)
    one[a] = 1e-3
    from solver.correction import influence_matrix, panel_ids

    ids = panel_ids(GRID, np.zeros((GRID.N, GRID.N)), LAYOUT)
    moved = influence_matrix(GRID, ids, LAYOUT, acts) @ one
    moved_panels = set(ids[ids >= 0][np.abs(moved) > 1e-9].tolist())
    assert moved_panels == set(acts.panels_of(a))
    # and at the corner itself, every panel's shape reaches the full stroke
    from solver.actuators import shape_functions

    for p in acts.panels_of(a):
        sup = acts.supports[p]
        k = [s[0] for s in sup].index(a)
        w = shape_functions(LAYOUT, p, sup, [acts.xy[a, 0]], [acts.xy[a, 1]])
        assert w[0, k] == pytest.approx(1.0, abs=1e-12)


def test_screws_reach_exactly_the_rigid_panel_floor():
    acts = screws_layout(LAYOUT)
    result = correct(GRID, _rng_map(2), LAYOUT, acts)
    assert result.rms_after == pytest.approx(result.within_panel_rms, rel=1e-9)
    # the corners' bilinear panels reach a little below it (their twist), never above much
    corners = correct(GRID, _rng_map(2), LAYOUT, corners_layout(LAYOUT))
    assert corners.rms_after > 0


def test_ranges_bound_the_commands():
    acts = corners_layout(LAYOUT)
    free = correct(GRID, _rng_map(), LAYOUT, acts)
    limit = 0.3 * np.max(np.abs(free.commands))
    bounded = build_layout(acts.ids, acts.xy, [acts.panels_of(a) for a in range(acts.n_actuators)],
                           np.tile([-limit, limit], (acts.n_actuators, 1)), LAYOUT)
    result = correct(GRID, _rng_map(), LAYOUT, bounded)
    assert np.max(np.abs(result.commands)) <= limit * (1 + 1e-9)
    # against bounded least squares on the dense system (points x actuators)
    from scipy.optimize import lsq_linear

    M, target = _dense_system(result.before, LAYOUT, acts)
    dense = lsq_linear(M, -target, bounds=(-limit, limit), method="bvls", tol=1e-14).x
    assert np.max(np.abs(result.commands - dense)) < 1e-6 * limit
    assert result.clipped > 0
    assert free.rms_after <= result.rms_after < result.rms_before


def test_ruze_matches_the_closed_form_on_a_gaussian_random_surface():
    rng = np.random.default_rng(7)
    sigma = 0.2e-3
    values = rng.normal(0.0, sigma, 200_000)
    measured = float(np.sqrt(np.mean(values**2)))
    f = np.array([10e9, 22e9, 43e9])
    lam = 299_792_458.0 / f
    # phase errors 4 pi delta / lambda, Gaussian: the mean of exp(i phase) squared is Ruze's law
    coherent = np.abs(np.mean(np.exp(1j * 4 * np.pi * values[:, None] / lam), axis=0)) ** 2
    np.testing.assert_allclose(ruze(measured, f), coherent, rtol=0.02, atol=2e-3)
    np.testing.assert_allclose(ruze(sigma, f), np.exp(-((4 * np.pi * sigma / lam) ** 2)), rtol=1e-12)


def test_noll_order():
    assert [noll_to_nm(j) for j in range(1, 12)] == [
        (0, 0), (1, 1), (1, -1), (2, 0), (2, -2), (2, 2), (3, -1), (3, 1), (3, -3), (3, 3), (4, 0)]


def test_zernike_fit_recovers_the_terms_that_made_the_surface():
    terms = [(2, 2, 30e-6), (3, -1, -12e-6), (4, 0, 5e-6), (2, 0, 8e-6)]
    grid = ApertureGrid(D, 200)
    X, Y = grid.XY
    delta = grid.masked(zernike_sum(terms, A, X, Y))
    fit = {(n, m): c for _, n, m, c in zernike_fit(grid, delta, 4)}
    for n, m, c in terms:
        assert fit[(n, m)] == pytest.approx(c, abs=0.02 * abs(c))
    others = [abs(c) for (n, m), c in fit.items() if (n, m) not in {(t[0], t[1]) for t in terms}]
    assert max(others) < 0.3e-6


def _surface_file(tmp_path, delta, std=None):
    attrs = {"solver": "test", "boundary": "test", "harmonic_part": "test", "removed_terms": "",
             "focal_length": 33.0, "diameter": D, "sphere_radius": 10.0}
    ds = surface.surfacemap(GRID, np.nan_to_num(delta), attrs, deformation_std=std)
    return surface.save(ds, tmp_path / "map.nc")


SCENE = """name = "t"
[dish]
diameter_m = 110.0
focal_length_m = 33.0
[panels]
ring_edges_m = [0.0, 13.75, 27.5, 41.25, 55.0]
panels_per_ring = [6, 12, 18, 24]
gap_m = 0.01
[source]
frequency_hz = 0.3e9
[sphere]
radius_m = 10.0
n_theta = 30
n_phi = 60
"""


def test_files_state_sign_unit_and_rms_and_carry_the_command_error(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE)
    delta = _rng_map()
    std = GRID.masked(np.full(delta.shape, 2e-6))
    path = _surface_file(tmp_path, delta, std)
    run = run_correct(path, tmp_path / "out", scene=scene, unit="mm", frequencies=[43e9],
                      remove="piston,tilt")
    text = (tmp_path / "out" / "commands.csv").read_text()
    assert "a positive command moves the surface" in text and "by that many mm" in text
    assert "RMS before" in text and "Ruze efficiency at 43 GHz" in text
    rows = list(csv.DictReader(line for line in text.splitlines() if not line.startswith("#")))
    got = np.array([float(r["command_mm"]) for r in rows]) * 1e-3
    np.testing.assert_allclose(got, run.correction.commands, atol=1e-7)
    toml = tomllib.loads((tmp_path / "out" / "commands.toml").read_text())
    assert toml["unit"] == "mm" and len(toml["actuator"]) == run.actuators.n_actuators
    for name in ("commands.toml", "zernike.csv", "summary.txt"):
        assert "a positive command moves the surface" in (tmp_path / "out" / name).read_text()
    residual = surface.load(tmp_path / "out" / "residual.nc")
    assert "a positive command moves the surface" in residual.attrs["command_sign"]
    assert np.nanstd(residual["deformation"].values) < np.nanstd(delta)
    # independent errors of 2 um per point: each command inherits a fraction of it, averaged
    # over its panels' points (many points per panel: far below 2 um, above 0)
    std_c = run.correction.command_std
    assert std_c is not None and np.all(std_c > 0) and np.median(std_c) < 2e-6
    # a Monte-Carlo check of the propagated command error
    rng = np.random.default_rng(3)
    acts = run.actuators
    trials = np.array([correct(GRID, delta + GRID.masked(rng.normal(0, 2e-6, delta.shape)), LAYOUT,
                               acts, ("piston", "tilt")).commands for _ in range(40)])
    spread = trials.std(axis=0)
    assert np.median(spread / std_c) == pytest.approx(1.0, abs=0.25)


def test_bad_layouts_are_refused(tmp_path):
    outside = tmp_path / "a.csv"
    outside.write_text("id,x_m,y_m,panels\na1,60.0,0.0,0\n")
    with pytest.raises(ActuatorError, match="outside the dish"):
        read_actuators(outside, LAYOUT)
    lonely = tmp_path / "b.toml"
    lonely.write_text('[[actuator]]\nid = "a"\nx_m = 5.0\ny_m = 1.0\npanels = [0]\n')
    with pytest.raises(ActuatorError, match="panel 1 is held by no actuator"):
        read_actuators(lonely, LAYOUT)
    with pytest.raises(ActuatorError, match="no corners"):
        corners_layout(PanelLayout((0.0, 10.0, 55.0), (1, 12)))


def test_an_actuator_file_round_trips_the_generated_layout(tmp_path):
    acts = corners_layout(LAYOUT)
    path = tmp_path / "acts.csv"
    with open(path, "w", newline="") as fh:
        fh.write("# comment line\nid,x_m,y_m,panels\n")
        for a in range(acts.n_actuators):
            fh.write(f"{acts.ids[a]},{float(acts.xy[a, 0])!r},{float(acts.xy[a, 1])!r},"
                     f"{' '.join(map(str, acts.panels_of(a)))}\n")
    read = read_actuators(path, LAYOUT)
    delta = _rng_map()
    np.testing.assert_allclose(correct(GRID, delta, LAYOUT, read).commands,
                               correct(GRID, delta, LAYOUT, acts).commands, atol=1e-12)


def test_budget_command_error_matches_monte_carlo_maps_drawn_from_the_budget():
    from solver.correction_budget import budget_shapes, command_std_from_budget, dirichlet_mode

    grid = ApertureGrid(D, 64)
    # a Dirichlet mode has unit norm over the disk (cells of h^2)
    assert np.sum(dirichlet_mode(grid, 3, 2, 1) ** 2) * grid.h**2 == pytest.approx(1.0, rel=0.03)
    modes = [(0, 1, (20e-6) ** 2), (2, 1, (15e-6) ** 2), (1, 2, (10e-6) ** 2), (5, 3, (5e-6) ** 2)]
    shapes = list(budget_shapes(grid, modes, rim_targets=16, target_std=10e-6))
    acts = corners_layout(LAYOUT)
    terms = ("piston", "tilt")
    predicted = command_std_from_budget(grid, LAYOUT, acts, terms, shapes)
    rng = np.random.default_rng(11)
    draws = []
    for _ in range(300):
        delta = sum(rng.normal(0.0, np.sqrt(v)) * f for f, v in shapes)
        draws.append(correct(grid, grid.masked(delta), LAYOUT, acts, terms).commands)
    spread = np.std(draws, axis=0)
    held = predicted > 0.1 * predicted.max()
    np.testing.assert_allclose(spread[held], predicted[held], rtol=0.25)
    assert np.sqrt(np.mean((spread - predicted) ** 2)) < 0.08 * np.sqrt(np.mean(predicted**2))


def test_the_command_writes_every_file_and_prints_the_summary(tmp_path):
    from tests.cli import run_cli

    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE)
    path = _surface_file(tmp_path, _rng_map())
    acts = tmp_path / "acts.toml"
    layout = screws_layout(LAYOUT)
    acts.write_text("".join(
        f'[[actuator]]\nid = "s{a}"\nx_m = {float(layout.xy[a, 0])!r}\ny_m = {float(layout.xy[a, 1])!r}\n'
        f"panels = {layout.panels_of(a)}\nmin_m = -20e-6\nmax_m = 20e-6\n" for a in range(layout.n_actuators)))
    out = run_cli("correct", str(path), "-o", str(tmp_path / "out"), "--scene", str(scene),
                  "--actuators", str(acts), "--unit", "mil", "--frequency", "43e9",
                  "--zernike-order", "3", cwd=tmp_path)
    assert out.code == 0, out.stderr
    assert "predicted after" in out.stdout and "Ruze efficiency at 43 GHz" in out.stdout
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        "commands.csv", "commands.toml", "residual.nc", "summary.txt", "zernike.csv"]
    rows = [line for line in (tmp_path / "out" / "zernike.csv").read_text().splitlines()
            if line[:1].isdigit()]
    assert len(rows) == 10   # Noll terms of radial order <= 3
    text = (tmp_path / "out" / "commands.csv").read_text()
    values = [float(line.rsplit(",", 1)[1]) for line in text.splitlines()[1:]
              if line and not line.startswith(("#", "id"))]
    assert max(abs(v) for v in values) <= 20e-6 / 25.4e-6 + 1e-4   # the range, in mil


def test_the_commands_files_read_back_as_actuator_files(tmp_path):
    # rim corners written to the micrometre must read back inside the dish, the command columns
    # and the TOML header are skipped, and an id with a quote and a backslash survives TOML
    acts = corners_layout(LAYOUT)
    ids = ('q"x\\' + acts.ids[0], *acts.ids[1:])
    named = build_layout(ids, acts.xy, [acts.panels_of(a) for a in range(acts.n_actuators)],
                         np.tile([-np.inf, np.inf], (acts.n_actuators, 1)), LAYOUT)
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE)
    first = tmp_path / "first.toml"
    first.write_text("".join(
        f'[[actuator]]\nid = "{named.ids[a].replace(chr(92), 2 * chr(92)).replace(chr(34), chr(92) + chr(34))}"'
        f"\nx_m = {float(named.xy[a, 0])!r}\ny_m = {float(named.xy[a, 1])!r}\n"
        f"panels = {named.panels_of(a)}\n" for a in range(named.n_actuators)))
    path = _surface_file(tmp_path, _rng_map())
    run = run_correct(path, tmp_path / "out", scene=scene, actuators=first)
    written = tomllib.loads((tmp_path / "out" / "commands.toml").read_text())
    assert written["actuator"][0]["id"] == ids[0]
    expected = _joint_reference(run.correction.before, LAYOUT, acts)  # piston, tilt removed
    for name in ("commands.csv", "commands.toml"):
        again = run_correct(path, tmp_path / name.replace(".", "_"), scene=scene,
                            actuators=tmp_path / "out" / name)
        assert again.actuators.ids == ids
        np.testing.assert_allclose(again.correction.commands, expected, atol=1e-9)


def _locked_layout(indices: list[int]):
    """The corner layout with the actuators at ``indices`` locked (min_m = max_m = 0), the others
    free within 1 m: (the layout, which are locked, the corner layout)."""
    acts = corners_layout(LAYOUT)
    locked = np.zeros(acts.n_actuators, dtype=bool)
    locked[indices] = True
    ranges = np.where(locked[:, None], 0.0, np.array([-1.0, 1.0]))
    bounded = build_layout(acts.ids, acts.xy, [acts.panels_of(a) for a in range(acts.n_actuators)],
                           ranges, LAYOUT)
    return bounded, locked, acts


def test_locked_actuators_stay_at_zero_and_the_others_fit_without_them():
    bounded, locked, acts = _locked_layout([3, 17, 40])
    result = correct(GRID, _rng_map(), LAYOUT, bounded)
    assert np.all(result.commands[locked] == 0.0)
    assert any("3 actuators locked" in note for note in result.notes)
    M, target = _dense_system(result.before, LAYOUT, acts)  # the bounds of +-1 m never bind
    sol, *_ = np.linalg.lstsq(M[:, ~locked], -target, rcond=None)
    np.testing.assert_allclose(result.commands[~locked], sol, atol=1e-9)


def _nan_file(tmp_path, delta):
    """A SurfaceMap file of ``delta`` with its NaN kept (points without data)."""
    attrs = {"solver": "test", "boundary": "test", "harmonic_part": "test", "removed_terms": "",
             "focal_length": 33.0, "diameter": D, "sphere_radius": 10.0}
    return surface.save(surface.surfacemap(GRID, delta, attrs), tmp_path / "gappy.nc")


def test_gaps_and_points_without_data_stay_nan_in_the_residual(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE.replace("gap_m = 0.01", "gap_m = 0.5"))
    delta = _rng_map()
    delta[40:44, 10:20] = np.nan  # a patch without data
    run_correct(_nan_file(tmp_path, delta), tmp_path / "out", scene=scene)
    residual = surface.load(tmp_path / "out" / "residual.nc")["deformation"].values
    X, Y = GRID.XY
    gaps = PanelLayout((0.0, 13.75, 27.5, 41.25, 55.0), (6, 12, 18, 24), 0.5).panel_at(X, Y) < 0
    surface_points = GRID.mask & ~gaps & np.isfinite(delta)
    assert np.isnan(residual[GRID.mask & gaps]).all() and (GRID.mask & gaps).sum() > 100
    assert np.isnan(residual[40:44, 10:20]).all()
    assert np.isfinite(residual[surface_points]).all()


def test_a_map_of_another_dish_or_grid_or_without_data_is_refused(tmp_path):
    from raysim.errors import RaysimError, SurfaceMapError
    from solver.errors import SolverError

    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE.replace("diameter_m = 110.0", "diameter_m = 50.0")
                     .replace("[0.0, 13.75, 27.5, 41.25, 55.0]", "[0.0, 5.0, 10.0, 15.0, 25.0]"))
    path = _surface_file(tmp_path, _rng_map())
    with pytest.raises(RaysimError, match="110 m dish, the panel layout of a 50 m one"):
        run_correct(path, tmp_path / "out", scene=scene)
    scene.write_text(SCENE)
    nothing = _nan_file(tmp_path, np.full(GRID.XY[0].shape, np.nan))
    with pytest.raises(SolverError, match="no finite deformation"):
        run_correct(nothing, tmp_path / "out", scene=scene)
    assert not (tmp_path / "out").exists()
    ds = surface.load(path)
    for edit, match in ((lambda d: d.isel(x=slice(20, 60), y=slice(20, 60)), "cell centres"),
                        (lambda d: d.isel(x=slice(0, 90)), "square"),
                        (lambda d: d.assign(deformation=d.deformation.fillna(0) + np.inf), "infinite")):
        bad = edit(ds)
        bad.to_netcdf(tmp_path / "bad.nc")
        with pytest.raises(SurfaceMapError, match=match):
            surface.load(tmp_path / "bad.nc")


def test_a_failing_run_leaves_the_output_folder_as_it_was(tmp_path):
    from solver.errors import SolverError

    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE)
    out = tmp_path / "out"
    (out / "residual.nc").mkdir(parents=True)
    (out / "summary.txt").write_text("an earlier run\n")
    with pytest.raises(SolverError, match="is a folder"):
        run_correct(_surface_file(tmp_path, _rng_map()), out, scene=scene)
    assert sorted(p.name for p in out.iterdir()) == ["residual.nc", "summary.txt"]
    assert (out / "summary.txt").read_text() == "an earlier run\n"


def test_a_flat_map_needs_no_correction(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE)
    run = run_correct(_surface_file(tmp_path, GRID.masked(np.zeros(GRID.XY[0].shape))),
                      tmp_path / "out", scene=scene)
    assert np.all(run.correction.commands == 0.0)
    assert "nothing to correct" in (tmp_path / "out" / "summary.txt").read_text()


@pytest.mark.parametrize(("text", "suffix", "match"), [
    ("id,x_m,y_m,panels,min_mm\na,1.0,1.0,0,0.1\n", ".csv", "unknown column min_mm"),
    ("id,x_m,y_m,panels,min_m,max_m\na,1.0,1.0,0,nan,nan\n", ".csv", "must be numbers"),
    ("actuator = 5\n", ".toml", "array of tables"),
    ('units = "mm"\n[[actuator]]\nid = "a"\nx_m = 1.0\ny_m = 1.0\npanels = [0]\n', ".toml",
     "unknown top-level key units"),
    (b"\xff\xfe\x00binary", ".csv", "not a text file"),
])
def test_unreadable_or_misspelt_actuator_files_are_refused(tmp_path, text, suffix, match):
    path = tmp_path / f"acts{suffix}"
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    with pytest.raises(ActuatorError, match=match):
        read_actuators(path, LAYOUT)


def test_options_that_cannot_apply_are_refused(tmp_path):
    from solver.errors import SolverError

    path = _surface_file(tmp_path, _rng_map())
    acts = tmp_path / "acts.csv"
    acts.write_text("id,x_m,y_m,panels\na,1.0,1.0,0\n")
    with pytest.raises(SolverError, match="--stroke bounds generated layouts"):
        run_correct(path, tmp_path / "out", actuators=acts, stroke=1e-5)
    with pytest.raises(SolverError, match="finite"):
        run_correct(path, tmp_path / "out", frequencies=[float("inf")])
    # GHz meant, or past any radio telescope: Ruze 1.00000 -> 1.00000 or 0.00000 was printed
    with pytest.raises(SolverError, match="is in Hz"):
        run_correct(path, tmp_path / "out", frequencies=[43.0])
    with pytest.raises(SolverError, match="10 THz"):
        run_correct(path, tmp_path / "out", frequencies=[43e12])
    with pytest.raises(SolverError, match="integer in 0..20"):
        run_correct(path, tmp_path / "out", zernike_order=4.5)
    assert not (tmp_path / "out").exists()
    with pytest.raises(ActuatorError, match="give 1 to 6"):
        screws_layout(LAYOUT, ((0.1, 0.1),) * 7)


def test_a_relative_source_fieldmap_is_read_from_the_maps_own_folder(tmp_path, monkeypatch):
    from solver.correction_io import source_fieldmap

    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "f.nc").write_bytes(b"")
    (tmp_path / "elsewhere.nc").write_bytes(b"")
    monkeypatch.chdir(tmp_path)  # a file of the same name here must not be taken
    (tmp_path / "f.nc").write_bytes(b"")

    def recorded(value):
        from types import SimpleNamespace

        return SimpleNamespace(attrs={"source_fieldmap": value})

    assert source_fieldmap(recorded("f.nc"), str(tmp_path / "run" / "s.nc")) == tmp_path / "run" / "f.nc"
    assert source_fieldmap(recorded(str(tmp_path / "elsewhere.nc")), "run/s.nc") == tmp_path / "elsewhere.nc"
    assert source_fieldmap(recorded("gone.nc"), "run/s.nc") is None
