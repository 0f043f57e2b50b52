"""raysim correct after the s16 QA: outputs that would destroy an input, the stroke ranges a
commands file carries back, command_std with locked actuators, actuators on panels they do
not touch, TOML booleans, the bounded fit with the removed terms free, commands the map does
not determine, the flat map and the units of the summary, and Ruze's half-path-length error.
Each against an independent reference (a dense least squares or a closed form)."""

import csv
import tomllib

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from raysim.surface.panels import PanelLayout
from solver import surface
from solver.actuators import ActuatorError, build_layout, corners_layout, read_actuators, screws_layout
from solver.correction import correct
from solver.correction_io import focal_length_for, run_correct
from solver.errors import SolverError
from tests.solver.test_correction import (
    GRID,
    LAYOUT,
    SCENE,
    _dense_system,
    _joint_reference,
    _locked_layout,
    _rng_map,
    _surface_file,
)

F = 33.0


def _scene(tmp_path, extra=""):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.replace("[source]", extra + "[source]"))
    return path


def _acts_csv(path, acts, ranges):
    """An actuator CSV of ``acts`` with ``ranges`` (m, (n, 2))."""
    with open(path, "w") as fh:
        fh.write("id,x_m,y_m,panels,min_m,max_m\n")
        for a in range(acts.n_actuators):
            fh.write(f"{acts.ids[a]},{float(acts.xy[a, 0])!r},{float(acts.xy[a, 1])!r},"
                     f"{' '.join(map(str, acts.panels_of(a)))},{float(ranges[a, 0])!r},{float(ranges[a, 1])!r}\n")
    return path


def _rows(path):
    text = path.read_text()
    return list(csv.DictReader(line for line in text.splitlines() if not line.startswith("#")))


# --- F1: an output must not be a file the run reads ---------------------------------------
def test_an_output_named_like_the_source_fieldmap_is_refused_and_it_survives(tmp_path):
    from raysim.maps.fieldmap import fieldmap
    from raysim.maps.fieldmap import save as save_fieldmap
    from raysim.maps.sphere import SphereGrid

    sphere = SphereGrid(10.0, 6, 12)
    ones = np.ones((6, 12))
    field = fieldmap(sphere, ones, ones, focal_length=F, diameter=110.0, frequency_hz=0.3e9,
                     method="measured", sampling="cell_mean", scene=SCENE)
    (tmp_path / "fmdir").mkdir()
    source = save_fieldmap(field, tmp_path / "fmdir" / "residual.nc")
    before = source.read_bytes()
    attrs = {"solver": "test", "boundary": "test", "harmonic_part": "test", "removed_terms": "",
             "focal_length": F, "diameter": 110.0, "sphere_radius": 10.0,
             "source_fieldmap": str(source)}
    smap = surface.save(surface.surfacemap(GRID, np.nan_to_num(_rng_map()), attrs), tmp_path / "s.nc")
    with pytest.raises(SolverError, match="residual.nc: is an input .*source FieldMap"):
        run_correct(smap, tmp_path / "fmdir")
    assert source.read_bytes() == before
    run_correct(smap, tmp_path / "elsewhere")  # the same map, the layout from that FieldMap


def test_an_output_named_like_a_file_the_scene_names_is_refused_and_it_survives(tmp_path):
    path = _surface_file(tmp_path, _rng_map())
    (tmp_path / "out").mkdir()
    named = tmp_path / "out" / "residual.nc"
    named.write_bytes(path.read_bytes())
    scene = _scene(tmp_path, '[[deformation]]\ntype = "map"\nfile = "out/residual.nc"\n')
    with pytest.raises(SolverError, match="residual.nc: is an input .*file the scene names"):
        run_correct(path, tmp_path / "out", scene=scene)
    assert named.read_bytes() == path.read_bytes()
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["residual.nc"]


# --- F2: the commands files keep the stroke ranges ---------------------------------------
def test_commands_files_read_back_with_their_ranges_and_locks(tmp_path):
    acts = corners_layout(LAYOUT)
    free = correct(GRID, _rng_map(), LAYOUT, acts, ("piston", "tilt"))
    limit = 0.4 * np.max(np.abs(free.commands))
    ranges = np.tile([-limit, limit], (acts.n_actuators, 1))
    ranges[[0, 10]] = 0.0  # two locked
    ranges[5] = [-np.inf, 0.5 * limit]  # one open at one end
    scene, path = _scene(tmp_path), _surface_file(tmp_path, _rng_map())
    first = run_correct(path, tmp_path / "out", scene=scene,
                        actuators=_acts_csv(tmp_path / "acts.csv", acts, ranges))
    assert first.correction.clipped > 0
    for name in ("commands.csv", "commands.toml"):
        back = read_actuators(tmp_path / "out" / name, LAYOUT)
        np.testing.assert_array_equal(back.ranges, ranges)
        again = run_correct(path, tmp_path / name.replace(".", "_"), scene=scene,
                            actuators=tmp_path / "out" / name)
        np.testing.assert_allclose(again.correction.commands, first.correction.commands, atol=1e-12)
        assert np.all(again.correction.commands[[0, 10]] == 0.0)


def test_a_stroke_run_writes_its_ranges(tmp_path):
    run_correct(_surface_file(tmp_path, _rng_map()), tmp_path / "out", scene=_scene(tmp_path),
                stroke=20e-6)
    back = read_actuators(tmp_path / "out" / "commands.toml", LAYOUT)
    np.testing.assert_array_equal(back.ranges, np.tile([-20e-6, 20e-6], (back.n_actuators, 1)))


# --- F3: command_std over the free actuators only ----------------------------------------
def test_command_std_with_locked_actuators_matches_a_dense_fit_without_their_columns():
    bounded, locked, acts = _locked_layout([0, 10, 33])
    delta = _rng_map()
    std = GRID.masked(np.full(delta.shape, 2e-6))
    result = correct(GRID, delta, LAYOUT, bounded, delta_std=std)
    M, _ = _dense_system(result.before, LAYOUT, acts)
    L = np.linalg.pinv(M[:, ~locked])  # commands = -L target; independent points of 2 um
    expected = 2e-6 * np.sqrt(np.sum(L * L, axis=1))
    assert np.all(result.command_std[locked] == 0.0)
    np.testing.assert_allclose(result.command_std[~locked], expected, rtol=1e-6)


# --- F4, F5: actuator files ----------------------------------------------------------------
def test_an_actuator_holding_a_panel_it_does_not_touch_is_refused(tmp_path):
    acts = corners_layout(LAYOUT)
    members = [acts.panels_of(a) for a in range(acts.n_actuators)]
    a = int(np.argmin(np.hypot(acts.xy[:, 0] - 13.75, acts.xy[:, 1])))  # the corner at (13.75, 0)
    far = next(p for p in range(LAYOUT.n_panels) if LAYOUT.ring(p) == 1 and p not in members[a]
               and LAYOUT.angular_limits(p)[0] > 1.0)
    members[a] = [*members[a], far]
    with pytest.raises(ActuatorError, match=f"actuator {acts.ids[a]} at .* from panel {far}, which"):
        build_layout(acts.ids, acts.xy, members, np.full((acts.n_actuators, 2), np.inf) * [-1, 1],
                     LAYOUT)
    # a corner 1 mm off and the screws inside their panels are accepted
    nudged = acts.xy.copy()
    nudged[a] += [0.0, 1e-3]
    build_layout(acts.ids, nudged, [acts.panels_of(k) for k in range(acts.n_actuators)],
                 np.full((acts.n_actuators, 2), np.inf) * [-1, 1], LAYOUT)
    screws = screws_layout(LAYOUT)
    build_layout(screws.ids, screws.xy, [screws.panels_of(k) for k in range(screws.n_actuators)],
                 np.full((screws.n_actuators, 2), np.inf) * [-1, 1], LAYOUT)


@pytest.mark.parametrize(("edit", "match"), [
    (("x_m = 13.75", "x_m = true"), "x_m = true is a boolean"),
    (("panels = [0]", "panels = [0, true]"), "integer panel ids, got True"),
    (("panels = [0]", "panels = [0.5]"), "integer panel ids, got 0.5"),
    (("max_m = 1e-4", "max_m = false"), "max_m = false is a boolean"),
])
def test_toml_booleans_and_fractions_are_no_numbers(tmp_path, edit, match):
    path = tmp_path / "a.toml"
    path.write_text('[[actuator]]\nid = "a"\nx_m = 13.75\ny_m = 0.1\npanels = [0]\nmin_m = -1e-4\n'
                    "max_m = 1e-4\n".replace(*edit))
    with pytest.raises(ActuatorError, match=match):
        read_actuators(path, PanelLayout((0.0, 20.0), (1,)))


def test_a_range_that_excludes_zero_names_the_file_and_the_actuator(tmp_path):
    acts = corners_layout(LAYOUT)
    ranges = np.tile([-1e-4, 1e-4], (acts.n_actuators, 1))
    ranges[7] = [1e-5, 1e-4]
    path = _acts_csv(tmp_path / "acts.csv", acts, ranges)
    with pytest.raises(ActuatorError, match=f"acts.csv: actuator {acts.ids[7]}: .* excludes 0"):
        read_actuators(path, LAYOUT)


# --- F6: bounded commands fitted jointly with the removed terms ---------------------------
@pytest.mark.parametrize("one_sided", [False, True])
def test_bounded_fit_takes_the_removed_terms_jointly(one_sided):
    acts = corners_layout(LAYOUT)
    delta = _rng_map(3)
    free = correct(GRID, delta, LAYOUT, acts, ("piston", "tilt"))
    # strokes of +-0.3 of the free fit's, or only upward (a piston makes up the rest)
    lo, hi = (0.0, 3.0) if one_sided else (-0.3, 0.3)
    lo, hi = np.array([lo, hi]) * np.max(np.abs(free.commands))
    bounded = build_layout(acts.ids, acts.xy, [acts.panels_of(a) for a in range(acts.n_actuators)],
                           np.tile([lo, hi], (acts.n_actuators, 1)), LAYOUT)
    result = correct(GRID, delta, LAYOUT, bounded, ("piston", "tilt"))
    # reference: commands bounded, piston and two tilts over the panel points unbounded
    M, target = _dense_system(delta, LAYOUT, acts)
    X, Y = GRID.XY
    ids = np.where(GRID.mask & np.isfinite(delta), LAYOUT.panel_at(X, Y), -1)
    G = np.stack([np.ones((ids >= 0).sum()), X[ids >= 0], Y[ids >= 0]], axis=-1)
    n = acts.n_actuators
    sol = lsq_linear(np.hstack([M, G]), -target, bounds=(np.r_[[lo] * n, [-np.inf] * 3],
                                                         np.r_[[hi] * n, [np.inf] * 3]),
                     method="trf", tol=1e-12, max_iter=5000).x
    best = np.sqrt(np.mean((target + np.hstack([M, G]) @ sol) ** 2))
    assert result.rms_after == pytest.approx(best, rel=1e-4)
    assert np.all((result.commands >= lo - 1e-12) & (result.commands <= hi + 1e-12))
    # the old route (terms off first, then the bounded fit) leaves more
    on = result.before[ids >= 0]
    sequential = lsq_linear(M, -on, bounds=(lo, hi), method="bvls").x
    old = np.sqrt(np.mean((on + M @ sequential) ** 2))
    assert old > (3.0 if one_sided else 1.001) * best
    if one_sided:  # upward strokes and a free piston reach what free strokes reach
        assert best == pytest.approx(free.rms_after, rel=1e-3)


@pytest.mark.parametrize("kind", ["corners", "screws"])
def test_without_bounds_the_commands_are_the_joint_least_squares(kind):
    """Commands and removed terms fitted together, the commands of least norm: no worse than
    fitting the terms first, and as good as a free stroke range that never binds (the two
    paths once differed: a --stroke of 10 mm shifted every command by a plane)."""
    acts = corners_layout(LAYOUT) if kind == "corners" else screws_layout(LAYOUT)
    result = correct(GRID, _rng_map(3), LAYOUT, acts, ("piston", "tilt"))
    ref = _joint_reference(result.before, LAYOUT, acts)
    np.testing.assert_allclose(result.commands, ref, atol=1e-9 * np.max(np.abs(ref)))
    M, target = _dense_system(result.before, LAYOUT, acts)
    first, *_ = np.linalg.lstsq(M, -target, rcond=None)
    assert result.rms_after <= np.sqrt(np.mean((target + M @ first) ** 2)) * (1 + 1e-9)
    wide = build_layout(acts.ids, acts.xy, [acts.panels_of(a) for a in range(acts.n_actuators)],
                        np.tile([-1.0, 1.0], (acts.n_actuators, 1)), LAYOUT)
    bounded = correct(GRID, _rng_map(3), LAYOUT, wide, ("piston", "tilt"))
    assert bounded.rms_after == pytest.approx(result.rms_after, rel=1e-6)


# --- F7: commands the map does not determine ------------------------------------------------
def test_a_panel_with_too_few_map_points_is_noted():
    acts = screws_layout(LAYOUT)  # three screws per panel, none shared
    X, Y = GRID.XY
    delta = _rng_map()
    ids = LAYOUT.panel_at(X, Y)
    sparse = np.flatnonzero(ids.ravel() == 40)
    delta.ravel()[sparse[2:]] = np.nan  # two map points left on panel 40: a line, not a plane
    result = correct(GRID, delta, LAYOUT, acts)
    M, _ = _dense_system(delta, LAYOUT, acts)
    _, s, vt = np.linalg.svd(M, full_matrices=True)
    null = vt[np.sum(s > s[0] * 1e-10):]
    loose = int(np.sum(np.linalg.norm(null, axis=0) > 1e-6))
    assert loose == 3
    assert any(f"{loose} actuators on 1 panels are not determined by the map" in note
               for note in result.notes)
    assert not any("not determined" in note
                   for note in correct(GRID, _rng_map(), LAYOUT, acts).notes)


# --- F8: a flat map, the units and digits of the files ----------------------------------
def test_a_map_flat_after_the_removed_terms_has_nothing_to_correct(tmp_path):
    X, Y = GRID.XY
    tilted = GRID.masked(30e-6 + 2e-6 * X - 1e-6 * Y)
    run = run_correct(_surface_file(tmp_path, tilted), tmp_path / "out", scene=_scene(tmp_path))
    text = (tmp_path / "out" / "summary.txt").read_text()
    assert "nothing to correct" in text and "% left" not in text
    assert np.max(np.abs(run.correction.commands)) < 1e-15


def test_the_command_error_is_in_the_unit_with_enough_digits(tmp_path):
    delta = _rng_map()
    std = GRID.masked(np.full(delta.shape, 0.05e-6))  # commands inherit about 0.01 um
    run = run_correct(_surface_file(tmp_path, delta, std), tmp_path / "out", scene=_scene(tmp_path),
                      unit="mm")
    text = (tmp_path / "out" / "summary.txt").read_text()
    assert "command error from the map's std (points taken as independent: a floor for an inverted map): median" in text and " um, max" not in text
    written = np.array([float(r["command_std_mm"]) for r in _rows(tmp_path / "out" / "commands.csv")])
    np.testing.assert_allclose(written * 1e-3, run.correction.command_std, atol=0.51e-10)
    assert np.all(written > 0)


# --- F9: Ruze's half-path-length error -------------------------------------------------------
def test_the_half_path_length_error_of_a_paraboloid_is_exact_and_ruze_uses_it(tmp_path):
    X, Y = GRID.XY
    c = 50e-6
    # dz = c (1 + rho^2 / 4F^2): the half path-length error dz / (1 + rho^2 / 4F^2) is c everywhere
    bowl = GRID.masked(c * (1 + (X**2 + Y**2) / (4 * F**2)))
    result = correct(GRID, bowl, LAYOUT, corners_layout(LAYOUT), focal_length=F)
    assert result.path_rms_before == pytest.approx(c, rel=1e-12)
    assert result.rms_before > 1.2 * c
    # a uniform piston c over the disk of radius a: RMS c / sqrt(1 + a^2 / 4F^2) (closed form)
    piston = GRID.masked(np.full(X.shape, c))
    run = run_correct(_surface_file(tmp_path, piston), tmp_path / "out", scene=_scene(tmp_path),
                      remove="none", frequencies=[43e9])
    expected = c / np.sqrt(1 + 55.0**2 / (4 * F**2))
    assert run.correction.rms_before == pytest.approx(c, rel=1e-12)
    assert run.correction.path_rms_before == pytest.approx(expected, rel=3e-3)
    lam = 299_792_458.0 / 43e9
    assert run.efficiency_before[0] == pytest.approx(
        np.exp(-(4 * np.pi * run.correction.path_rms_before / lam) ** 2), rel=1e-12)
    for name in ("summary.txt", "commands.csv", "commands.toml"):
        text = (tmp_path / "out" / name).read_text()
        assert "half-path-length" in text and "F = 33 m" in text
    assert tomllib.loads((tmp_path / "out" / "commands.toml").read_text())["unit"] == "um"


def test_the_focal_length_comes_from_the_map_else_the_scene_else_a_note():
    from types import SimpleNamespace

    scene = SimpleNamespace(dish=SimpleNamespace(focal_length=40.0))
    assert focal_length_for(SimpleNamespace(attrs={"focal_length": 33.0}), scene) == (33.0, "")
    assert focal_length_for(SimpleNamespace(attrs={}), scene) == (40.0, "")
    F_none, note = focal_length_for(SimpleNamespace(attrs={}), None)
    assert F_none is None and "no focal_length" in note and "axial RMS" in note


def test_a_spreadsheets_byte_order_mark_reads_and_a_panel_named_twice_is_said(tmp_path):
    """A CSV saved as "CSV UTF-8" starts with a byte-order mark: its first column read as
    "\\ufeffid", refused as unknown under a name that printed as "id". A panel named twice in
    one actuator's panels ("0;0") counted each actuator twice: "its 6 actuators do not fix a
    panel shape" of a panel held by 3."""
    acts = corners_layout(LAYOUT)
    plain = _acts_csv(tmp_path / "plain.csv", acts, np.tile([-np.inf, np.inf], (acts.n_actuators, 1)))
    marked = tmp_path / "marked.csv"
    marked.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())
    a, b = read_actuators(plain, LAYOUT), read_actuators(marked, LAYOUT)
    assert a.ids == b.ids and np.array_equal(a.xy, b.xy)
    twice = tmp_path / "twice.csv"
    lines = plain.read_text().splitlines()
    first = lines[1].split(",")
    first[3] = f"{first[3].split()[0]};{first[3].split()[0]}"
    twice.write_text("\n".join([lines[0], ",".join(first), *lines[2:]]) + "\n")
    with pytest.raises(ActuatorError, match=f"panel {first[3].split(';')[0]} is named twice"):
        read_actuators(twice, LAYOUT)


def test_the_commands_summary_repeats_what_the_map_may_not_hold(paper_field, tmp_path):
    """QA: a map `invert` flagged as mostly noise (and without rim targets, from GO data on a
    panelled dish) got commands whose summary predicted 47 -> 16 um with no word, while the
    commands made the true dish worse (25 -> 32 um). The summary now repeats the map's warning
    and says what the prediction leaves out; a clean map gets no warning line."""
    from solver.invert import invert

    field = paper_field.copy(deep=True)
    i = field["intensity"].values
    draw = np.random.default_rng(3).standard_normal(i.shape)
    field["intensity"] = (("theta", "phi"), i * 10 ** (0.1 * draw / 10))
    noisy = invert(field, N=64, refine_iterations=0, truth=None)
    assert "noise_warning" in noisy.attrs
    clean = invert(paper_field, N=64, refine_iterations=0, truth=None)
    scene = _scene(tmp_path)
    lines = {}
    for name, smap in (("noisy", noisy), ("clean", clean)):
        surface.save(smap, tmp_path / f"{name}.nc")
        run = run_correct(tmp_path / f"{name}.nc", tmp_path / name, scene=scene)
        lines[name] = (tmp_path / name / "summary.txt").read_text().splitlines()
        assert any("panel's piston" in t for t in lines[name]) and any(
            "harmonic part" in t and "UNOBSERVABLE" in t for t in lines[name]), run
    assert f"WARNING (the map's, from raysim invert): {noisy.attrs['noise_warning']}" in lines["noisy"]
    assert not any(t.startswith("WARNING") for t in lines["clean"])
