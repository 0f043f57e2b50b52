"""raysim correct after the QA of what the rig crew loads: a map in the wrong unit is refused
(not turned into commands of -167 m beside a note), the map's and the run's warnings reach
commands.csv and commands.toml (not only the console), and an actuator row with an empty id or
no panels is refused (a command nobody can address; an actuator silently commanded 0)."""

import csv
import tomllib

import numpy as np
import pytest

from raysim.errors import SurfaceMapError
from solver import surface
from solver.actuators import ActuatorError, corners_layout, read_actuators
from solver.correction import correct
from solver.correction_io import run_correct
from tests.solver.test_correction import GRID, LAYOUT, SCENE, _rng_map, _surface_file
from tests.solver.test_correction_qa import _acts_csv

TERMS = ("piston", "tilt")


def _scene(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE)
    return path


def _peak(delta):
    """The largest |departure| (m) of ``delta`` over the panels, piston and tilt removed."""
    return float(np.nanmax(np.abs(correct(GRID, delta, LAYOUT, corners_layout(LAYOUT), TERMS).before)))


# --- 1: a map in the wrong unit -------------------------------------------------------------
def test_a_map_departing_by_more_than_a_reflector_can_is_refused():
    """QA: a map in um stored as m (a 189 um bump read as 189 m) gave commands of -167 m and a
    note. A departure over 10 cm (piston and tilt off) is refused; one under it still gives
    commands."""
    acts = corners_layout(LAYOUT)
    with pytest.raises(SurfaceMapError, match=r"departs by up to \d+(\.\d+)? m from the dish .*"
                                              "is the deformation in metres"):
        correct(GRID, _rng_map() * 1e6, LAYOUT, acts, TERMS)
    unit = _rng_map() / _peak(_rng_map())  # departs by up to 1 m
    kept = correct(GRID, unit * 0.09, LAYOUT, acts, TERMS)
    assert np.all(np.isfinite(kept.commands)) and np.max(np.abs(kept.commands)) > 0.01
    with pytest.raises(SurfaceMapError, match="departs by up to 0.11 m"):
        correct(GRID, unit * 0.11, LAYOUT, acts, TERMS)


def test_the_command_refuses_a_map_in_micrometres_and_writes_nothing(tmp_path, raysim_cli):
    scene = _scene(tmp_path)
    good = _surface_file(tmp_path, _rng_map())
    kept = tmp_path / "kept"
    assert raysim_cli("correct", str(good), "-o", str(kept), "--scene", str(scene)).code == 0
    before = {p.name: p.read_bytes() for p in kept.iterdir()}
    wrong = surface.save(surface.surfacemap(GRID, np.nan_to_num(_rng_map() * 1e6),
                                            dict(surface.load(good).attrs)), tmp_path / "um.nc")
    for out in (tmp_path / "new", kept):
        result = raysim_cli("correct", str(wrong), "-o", str(out), "--scene", str(scene))
        assert result.code == 2, result.stdout
        line = result.error()
        assert line.startswith(f"error: {wrong}: the map departs by up to ")
        assert "is the deformation in metres?" in line and "Traceback" not in result.stderr
    assert not (tmp_path / "new").exists()
    assert {p.name: p.read_bytes() for p in kept.iterdir()} == before


# --- 2: the warnings reach the files the crew loads --------------------------------------
def _csv_parts(path):
    """(comment lines, actuator rows) of a commands.csv."""
    lines = path.read_text().splitlines()
    comments = [line for line in lines if line.startswith("#")]
    rows = list(csv.DictReader(line for line in lines if not line.startswith("#")))
    return comments, rows


def test_the_maps_and_the_runs_warnings_reach_the_commands_files(tmp_path):
    """QA: invert's warnings carried by the map and correct's own notes were printed, but the
    commands files the crew loads said nothing. Each is now a comment line of commands.csv (one
    line each: a line break in an attribute must not start a row) and an entry of the TOML's
    ``warnings``; both files still read back as actuator files, with the same commands."""
    scene = _scene(tmp_path)
    delta = _rng_map()
    attrs = dict(surface.load(_surface_file(tmp_path, delta)).attrs)
    attrs.update(noise_warning="the map is mostly noise:\nits RMS is 80 % noise",
                 refine_warning="refinement did not converge")
    noisy = surface.save(surface.surfacemap(GRID, np.nan_to_num(delta), attrs), tmp_path / "noisy.nc")
    acts = corners_layout(LAYOUT)
    ranges = np.tile([-1e-3, 1e-3], (acts.n_actuators, 1))
    ranges[[3, 8]] = 0.0  # two locked: a note of correct's own
    path = _acts_csv(tmp_path / "acts.csv", acts, ranges)
    run = run_correct(noisy, tmp_path / "out", scene=scene, actuators=path)
    expected = ["WARNING (the map's, from raysim invert): the map is mostly noise: its RMS is 80 % noise",
                "WARNING (the map's, from raysim invert): refinement did not converge",
                "2 actuators locked (min_m = max_m = 0): commanded 0"]
    comments, rows = _csv_parts(tmp_path / "out" / "commands.csv")
    warned = tomllib.loads((tmp_path / "out" / "commands.toml").read_text())["warnings"]
    for line in expected:
        assert line in warned
        assert f"# {line}" in comments or f"# WARNING: {line}" in comments
    assert len(warned) == len(run.correction.notes) and len(rows) == acts.n_actuators
    summary = (tmp_path / "out" / "summary.txt").read_text()
    assert all(" ".join(w.split()[:6]) in summary for w in warned)
    for name in ("commands.csv", "commands.toml"):
        again = run_correct(noisy, tmp_path / name.replace(".", "_"), scene=scene,
                            actuators=tmp_path / "out" / name)
        assert again.actuators.ids == acts.ids
        np.testing.assert_allclose(again.correction.commands, run.correction.commands, atol=1e-12)
    # a clean map and plain actuators: nothing to warn of, said as an empty list
    run_correct(_surface_file(tmp_path, delta), tmp_path / "clean", scene=scene)
    assert tomllib.loads((tmp_path / "clean" / "commands.toml").read_text())["warnings"] == []
    assert not any("WARNING" in line for line in _csv_parts(tmp_path / "clean" / "commands.csv")[0])


# --- 3: actuator rows nobody can address ----------------------------------------------------
@pytest.mark.parametrize(("name", "row", "match"), [
    ("a.csv", ",{x},{y},{p}", r"a.csv: actuator row 2: its id is empty"),
    ("a.csv", "  ,{x},{y},{p}", r"a.csv: actuator row 2: its id is empty"),
    ("a.csv", "b,{x},{y},", r"a.csv: actuator row 2 \(actuator b\): its panels are empty"),
    ("a.toml", '[[actuator]]\nid = ""\nx_m = {x}\ny_m = {y}\npanels = [{p}]',
     r"a.toml: actuator row 2: its id is empty"),
    ("a.toml", '[[actuator]]\nid = "b"\nx_m = {x}\ny_m = {y}\npanels = []',
     r"a.toml: actuator row 2 \(actuator b\): its panels are empty"),
])
def test_an_actuator_without_id_or_panels_is_refused(tmp_path, name, row, match):
    """QA: an empty id got a command nobody can address; empty panels left the actuator
    commanded 0 and its panel's shape model silently another (it held no panel)."""
    acts = corners_layout(LAYOUT)
    x, y = (float(v) for v in acts.xy[1])
    panels = acts.panels_of(1)
    good = (f"a,{x!r},{y!r},{' '.join(map(str, panels))}" if name.endswith(".csv") else
            f'[[actuator]]\nid = "a"\nx_m = {x!r}\ny_m = {y!r}\npanels = {panels}')
    head = "id,x_m,y_m,panels\n" if name.endswith(".csv") else ""
    path = tmp_path / name
    path.write_text(head + good + "\n" + row.format(x=repr(x), y=repr(y), p=panels[0]) + "\n")
    with pytest.raises(ActuatorError, match=match):
        read_actuators(path, LAYOUT)
