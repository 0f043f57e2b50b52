"""A scan with a polarised probe through the simulated rig: the rig file's [probe], the map it
scans read by the same probe, and the measured FieldMap's ideal read by it too.

The simulated map is GO's of the ideal dish (F = 33 m, D = 110 m, R = 10 m) read by the probe:
its reading over the ideal paraboloid's law (rho / R)^2 is the probe's response to the ideal
reflected polarisation. The scan's ``intensity_ideal`` is that response written in closed form
(:func:`raysim.maps.probe.ideal_weight`), so a like-for-like scan of the ideal dish gives
I / I_ideal = 1, which it would miss by per cents with the bare (rho / R)^2.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from hardware.errors import PlanError
from hardware.plan import load_plan
from hardware.rig import load_rig
from hardware.session import scan
from raysim.maps import fieldmap as fieldmaps
from raysim.maps.probe import Probe, probe_of
from raysim.maps.sphere import ideal_go_intensity
from raysim.scene import parse_scene
from raysim.simulate import simulate

from .conftest import D, F, R, write_plan

SCENE = f"""
[dish]
diameter_m = {D}
focal_length_m = {F}
resolution_m = 0.5
[source]
frequency_hz = 3.0e8
[sphere]
radius_m = {R}
n_theta = 18
n_phi = 90
theta_max_deg = 72.0
"""


def probe_scan(tmp_path: Path, angle: float, map_angle: float | None = None):
    """Scan the ideal dish's GO map (read by a probe at ``map_angle`` deg, default ``angle``)
    with a rig whose probe is polarised at ``angle`` deg; the plan's 3 x 6 cells of 20 x 60 deg
    are centred at theta 10, 30, 50 and phi 30, 90, ..., 330 deg."""
    plan_path = write_plan(tmp_path)
    rig = tmp_path / "rig.toml"
    rig.write_text(rig.read_text() + f"\n[probe]\npolarization_deg = {angle}\npattern_q = 2.0\n")
    map_angle = angle if map_angle is None else map_angle
    field = simulate(parse_scene(SCENE + f"[probe]\npolarization_deg = {map_angle}\n"
                                 "pattern_q = 2.0\n"), "go")
    fieldmaps.save(field, tmp_path / "field.nc")
    plan = load_plan(plan_path)
    return plan, field, lambda: scan(plan, tmp_path / "scan.nc",
                                     simulate=tmp_path / "field.nc").fieldmap


@pytest.mark.parametrize("angle", [0.0, 90.0])
def test_scan_reads_what_the_probe_reads(tmp_path: Path, angle: float) -> None:
    plan, field, run = probe_scan(tmp_path, angle)
    assert plan.rig.probe_response == Probe(math.radians(angle), 2.0)
    ds = run()
    assert probe_of(ds) == plan.rig.probe_response
    assert ds.attrs["polarization"] == 0.0
    ratio = ds["intensity"].values / ds["intensity_ideal"].values
    theta = ds["theta"].values
    bare = ds["intensity_ideal"].values / ideal_go_intensity(theta, F, R, D)[:, None]
    if angle == 0.0:  # co-polar: the ideal dish reads as its ideal everywhere
        assert np.abs(ratio - 1).max() < 1e-3
        assert np.abs(bare - 1).max() > 1e-2  # the bare law would be off by far more
        return
    # cross-polar: the simulated meter adds the map's departure from its own ideal (none
    # here: the dish is ideal) to the probe's exact reading at the point, which vanishes in
    # the phi = 90 and 270 deg planes; elsewhere the scan reads the ideal it is compared with
    phi = np.degrees(ds["phi"].values)
    planes = np.isclose(phi, 90.0) | np.isclose(phi, 270.0)
    reading = ds["intensity"].values
    assert np.all(reading[:, planes] <= 1e-12)  # the simulated meter's floor
    assert np.abs(ratio[:, ~planes] - 1).max() < 1e-9
    # the map's own GO cross-polar cells away from the planes: the probe's closed form within
    # 2 % beyond theta = 20 deg (near the axis the 0.5 m mesh's tubes span several 4 deg cells)
    lit = theta > math.radians(20.0)
    cells = field["intensity"].sel(theta=ds["theta"], phi=ds["phi"], method="nearest").values
    assert np.abs(cells[lit][:, ~planes] / reading[lit][:, ~planes] - 1).max() < 2e-2
    assert bare[lit][:, ~planes].max() < 0.1  # a cross-polar probe sees a tenth at most


def test_scan_refuses_a_map_of_another_probe(tmp_path: Path) -> None:
    plan, _, run = probe_scan(tmp_path, 0.0, map_angle=90.0)
    with pytest.raises(PlanError, match="was simulated with the probe 'polarised at 90 deg"):
        run()
    plan, _, _ = probe_scan(tmp_path / "same", 0.0)
    other = dataclasses.replace(plan, polarization=math.radians(30.0))
    with pytest.raises(PlanError, match="incident wave polarised at 0 deg, the plan at 30 deg"):
        scan(other, tmp_path / "scan.nc", simulate=tmp_path / "same" / "field.nc")


def test_rig_probe_table(tmp_path: Path) -> None:
    path = tmp_path / "rig.toml"
    path.write_text("[track]\nradius_m = 10.0\n[probe]\npolarization_deg = 45.0\n"
                    "pattern = [[0.0, 1.0], [10.0, 0.8], [30.0, 0.1]]\n")
    rig, _ = load_rig(path)
    probe = rig.probe_response
    assert probe.polarization == pytest.approx(math.pi / 4)
    assert probe.pattern(math.radians(5.0)) == pytest.approx(0.9)
    assert probe.pattern(math.radians(50.0)) == pytest.approx(0.1)  # held beyond the table
    path.write_text("[track]\nradius_m = 10.0\n")
    assert load_rig(path)[0].probe_response.ideal
