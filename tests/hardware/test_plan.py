"""Scan plans: the acquisition order, the references and the checks on plan values."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import pytest

from hardware.errors import PlanError
from hardware.plan import REFERENCE, SAMPLE, load_plan

from .conftest import ROOT, write_plan


def test_order_alternates_and_references_every_k_lines(tmp_path: Path) -> None:
    plan = load_plan(write_plan(tmp_path, theta_step=20.0, phi_step=60.0, every=2))
    steps = plan.steps()
    kinds = [s.kind for s in steps]
    # 3 theta x 6 phi cells; references before line 0 and after lines 1, 3, 5
    assert kinds.count(SAMPLE) == 18
    assert [s.index for s in steps if s.kind == REFERENCE] == [0, 7, 14, 21]
    assert [s.index for s in steps] == list(range(len(steps)))
    lines = [[(s.i, s.j) for s in steps if s.kind == SAMPLE and s.j == j] for j in range(6)]
    assert lines[0] == [(0, 0), (1, 0), (2, 0)]
    assert lines[1] == [(2, 1), (1, 1), (0, 1)]
    assert lines[4] == [(0, 4), (1, 4), (2, 4)]
    # every cell exactly once, at its centre
    cells = {(s.i, s.j): s for s in steps if s.kind == SAMPLE}
    assert len(cells) == 18
    assert math.degrees(cells[(1, 2)].theta) == pytest.approx(30.0)
    assert math.degrees(cells[(1, 2)].phi) == pytest.approx(150.0)


def test_last_line_is_followed_by_a_reference(tmp_path: Path) -> None:
    plan = load_plan(write_plan(tmp_path, phi_step=72.0, every=2))  # 5 lines
    refs = [s.index for s in plan.steps() if s.kind == REFERENCE]
    assert refs == [0, 7, 14, 18]


def test_demo_plan_loads_and_fits_the_rig() -> None:
    plan = load_plan(ROOT / "scenes" / "scan_demo.toml")
    assert (plan.grid.n_theta, plan.grid.n_phi) == (8, 12)
    assert plan.grid.radius == 10.0
    assert plan.power_unit == pytest.approx(1e-5)
    assert plan.simulator.noise_db == 0.01
    assert len(plan.steps()) == 96 + 5
    assert (plan.reference_samples, plan.drift_correction, plan.drift_window) == (64, "auto", 9)


def test_fingerprint_follows_what_decides_the_samples(tmp_path: Path) -> None:
    a = load_plan(write_plan(tmp_path / "a"))
    b = load_plan(write_plan(tmp_path / "b"))
    c = load_plan(write_plan(tmp_path / "c", samples=3))
    d = load_plan(write_plan(tmp_path / "d", drift_correction="none"))
    e = load_plan(write_plan(tmp_path / "e", reference_samples=5))
    assert a.fingerprint() == b.fingerprint()
    assert a.fingerprint() != c.fingerprint()
    assert a.fingerprint() != e.fingerprint()
    # the drift correction only post-processes the journal's readings
    assert a.fingerprint() == d.fingerprint() and d.drift_correction == "none"
    assert a.fingerprint({"sim_noise_db": 0.0}) != a.fingerprint({"sim_noise_db": 0.01})


@pytest.mark.parametrize(("old", "new", "message"), [
    ("theta_step_deg = 20.0", "theta_step_deg = 25.0", "whole number of 25 deg steps"),
    ("theta_max_deg = 60.0", "theta_max_deg = 95.0", "must be <= 90"),
    ("samples_per_point = 2", "samples_per_point = 0", "must be >= 1"),
    ("focal_length_m = 33.0", "focal_length_m = 9.0", "must be below F"),
    ("power_unit_dbm = -20.0", "power_unit_dbm = \"loud\"", "must be a number"),
    ("seed = 3", "seed = 3\nnoise = 0.1", "unknown key 'simulator.noise' .did you mean 'noise_db'"),
    ("phi_max_deg = 360.0", "phi_max_deg = 420.0", "exceeds 360 deg"),
    # a grid wholly beyond the rim image (79.6 deg) ran to its end, then "no ideal intensity"
    ("theta_min_deg = 0.0\ntheta_max_deg = 60.0\ntheta_step_deg = 20.0",
     "theta_min_deg = 80.0\ntheta_max_deg = 90.0\ntheta_step_deg = 10.0",
     "starts at theta 80 deg, beyond the rim image .theta 79.61 deg"),
    ("[reflector]", "[reflectr]", "missing table [reflector]"),
    ('drift_correction = "smooth"', 'drift_correction = "spline"',
     "must be one of auto, none, linear, smooth"),
])
def test_bad_plan_values(tmp_path: Path, old: str, new: str, message: str) -> None:
    path = write_plan(tmp_path)
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))
    with pytest.raises(PlanError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_plan(path)


def test_plan_out_of_reach(tmp_path: Path) -> None:
    path = write_plan(tmp_path)
    rig = tmp_path / "rig.toml"
    text = rig.read_text().replace("slider_max_deg = 95.0", "slider_max_deg = 40.0")
    rig.write_text(text.replace("slider_deg = 95.0", "slider_deg = 30.0"))
    with pytest.raises(PlanError, match="out of the rig's reach"):
        load_plan(path)


def test_missing_rig_file(tmp_path: Path) -> None:
    path = write_plan(tmp_path)
    (tmp_path / "rig.toml").unlink()
    with pytest.raises(PlanError, match="no such rig file"):
        load_plan(path)


def test_duration_counts_moves_settling_and_readings(tmp_path: Path) -> None:
    """2 theta x 2 phi cells, a reference after every line, counted by hand: the rotation
    limits (-5..185 deg) send phi = 270 deg to rotation 90 deg with the slider negative, and
    both axes move at once at 10 deg/s, so each move takes its larger angle's time."""
    plan = load_plan(write_plan(tmp_path, theta_max=40.0, theta_step=20.0, phi_step=180.0,
                                samples=3, every=1, reference_samples=2))
    # axes (slider, rotation) in deg: ref (0, 0); line 0: (10, 90), (30, 90); ref;
    # line 1 reversed: (-30, 90), (-10, 90); ref
    moves_deg = [90, 20, 90, 90, 20, 90]
    readings = 4 * 3 + 3 * 2
    plan = replace(plan, settle_s=0.5, reading_s=0.1)
    assert plan.duration() == pytest.approx(sum(moves_deg) / 10.0 + 7 * 0.5 + readings * 0.1)
    assert plan.duration(5) - plan.duration() == pytest.approx(4 * 2 * 0.1)
