"""raysim correct after the QA of what the rig crew loads: a map in the wrong unit is refused
(not turned into commands of -167 m beside a note)."""

import numpy as np
import pytest

from raysim.errors import SurfaceMapError
from solver import surface
from solver.actuators import corners_layout
from solver.correction import correct
from tests.solver.test_correction import GRID, LAYOUT, SCENE, _rng_map, _surface_file

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
