"""Rig kinematics: commanded (theta, phi) -> axes -> probe position, and the rig file."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hardware.errors import PlanError
from hardware.rig import Calibration, Limits, Rig, load_rig

DIRECTIONS = [(math.radians(t), math.radians(p)) for t in (0.5, 10.0, 45.0, 79.6, 89.5)
              for p in (0.5, 90.0, 179.5, 180.5, 270.0, 359.5)]


def point(theta: float, phi: float, r: float) -> np.ndarray:
    """Cartesian point from the focus, independent of the rig module."""
    return r * np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                         -math.cos(theta)])


def test_perfect_rig_axes_are_the_angles() -> None:
    """Without calibration errors: slider = theta, rotation = phi (or phi - 360 deg) where
    the rotation limits [-5, 185] deg allow it, else slider = -theta, rotation = phi - 180."""
    rig = Rig(radius=10.0)
    for theta, phi in DIRECTIONS:
        slider, rotation = rig.axes(theta, phi)
        phi_deg = math.degrees(phi)
        near = [a for a in (phi_deg, phi_deg - 360.0) if -5.0 <= a <= 185.0]
        if near:
            assert slider == pytest.approx(theta, abs=1e-12)
            assert math.degrees(rotation) == pytest.approx(near[0], abs=1e-10)
        else:
            assert slider == pytest.approx(-theta, abs=1e-12)
            assert math.degrees(rotation) == pytest.approx(phi_deg - 180.0, abs=1e-10)


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.002), (0.003, -0.001, 0.0), (0.02, 0.01, -0.03)])
def test_round_trip_with_centre_offset_and_zeros(offset: tuple[float, float, float]) -> None:
    """axes() then probe() returns the commanded direction; the probe lies on the track
    circle around the offset centre and on the commanded ray from the focus."""
    cal = Calibration(centre_offset=offset, slider_zero=math.radians(1.5),
                      rotation_zero=math.radians(-2.0))
    rig = Rig(radius=10.0, calibration=cal)
    c = np.array(offset)
    for theta, phi in DIRECTIONS:
        slider, rotation = rig.axes(theta, phi)
        t, p, r = rig.probe(slider, rotation)
        assert t == pytest.approx(theta, abs=1e-12)
        assert math.cos(p - phi) == pytest.approx(1.0, abs=1e-12)
        probe = point(theta, phi, r)
        assert np.linalg.norm(probe - c) == pytest.approx(10.0, abs=1e-12)
        # first order: r = R + d.c for a small offset
        d = point(theta, phi, 1.0)
        assert r == pytest.approx(10.0 + d @ c, abs=2 * (c @ c) / 10.0 + 1e-12)


def test_probe_of_axes_matches_geometry() -> None:
    """probe() for known axis readings: the zeros are subtracted, then the track geometry."""
    cal = Calibration(centre_offset=(0.0, 0.0, 0.0), slider_zero=math.radians(2.0),
                      rotation_zero=math.radians(10.0))
    rig = Rig(radius=10.0, calibration=cal)
    theta, phi, r = rig.probe(math.radians(32.0), math.radians(100.0))
    assert math.degrees(theta) == pytest.approx(30.0, abs=1e-10)
    assert math.degrees(phi) == pytest.approx(90.0, abs=1e-10)
    assert r == pytest.approx(10.0, abs=1e-12)
    theta, phi, _ = rig.probe(math.radians(-28.0), math.radians(100.0))
    assert math.degrees(theta) == pytest.approx(30.0, abs=1e-10)
    assert math.degrees(phi) == pytest.approx(270.0, abs=1e-10)


def test_out_of_reach_is_a_plan_error() -> None:
    rig = Rig(radius=10.0, limits=Limits(slider_min=0.0, slider_max=math.radians(60.0),
                                         rotation_min=0.0, rotation_max=math.radians(90.0)))
    assert rig.axes(math.radians(30.0), math.radians(45.0)) == pytest.approx(
        (math.radians(30.0), math.radians(45.0)))
    with pytest.raises(PlanError, match="out of the rig's reach"):
        rig.axes(math.radians(70.0), math.radians(45.0))
    with pytest.raises(PlanError, match="out of the rig's reach"):
        rig.axes(math.radians(30.0), math.radians(200.0))


def test_sample_rig_file_loads() -> None:
    rig, text = load_rig(Path(__file__).resolve().parents[2] / "scenes" / "rig.toml")
    assert rig.radius == 10.0
    assert rig.park == pytest.approx((math.radians(95.0), 0.0))
    assert rig.within_limits(*rig.park)
    assert rig.speed == pytest.approx(math.radians(10.0))
    assert set(rig.resources) == {"meter", "motion"}
    assert "[track]" in text


@pytest.mark.parametrize(("snippet", "message"), [
    ("[track]\nradius_m = 10.0\nradius = 3.0\n", "unknown key 'track.radius' .did you mean 'radius_m'"),
    ("[track]\nradius_m = -1.0\n", "'track.radius_m' must be > 0"),
    ("[track]\nradius_m = 10.0\ncentre_offset_m = [0.0, 1.0]\n", "'track.centre_offset_m' must be 3 numbers [x, y, z]"),
    ("[track]\nradius_m = 10.0\n[park]\nslider_deg = 120.0\n", "park position lies outside"),
    ("[track]\nradius_m = 10.0\n[motion]\nslider_axis = 2\n", "distinct ESP301 axes"),
    ("[limits]\nslider_min_deg = 0\n", "missing table [track]"),
])
def test_bad_rig_files(tmp_path: Path, snippet: str, message: str) -> None:
    path = tmp_path / "rig.toml"
    path.write_text(snippet)
    with pytest.raises(PlanError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_rig(path)
