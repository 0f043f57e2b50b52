"""Scan plans with obstacles: the measured FieldMap marks the cells a feed cabin and legs hide.

The reference for the marks is plain geometry, without rays or meshes: a cell of the plan's
grid maps to the aperture annulus r = 2F tan(theta/2) between its theta edges. The cabin (a
disk of radius r_c at the focus) hides every cell with r < r_c on the way in (the reflected
rays end on the sphere before the focus height); a leg, seen along the axis, hides a strip of
its width along its azimuth between the apex's radius and the foot's, and nothing else inside
the foot (there the leg lies above the reflected ray's whole path). Shapes are grown or shrunk
by a margin of two ray spacings (a GO tube with one blocked ray is dropped whole). Then the
same geometry is simulated as a scene, and the scan of it through the simulated rig must
carry the scene's marks, obstacles and blocked ideal.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from hardware.errors import PlanError
from hardware.plan import load_plan
from hardware.session import scan
from raysim.maps import fieldmap as fieldmaps
from raysim.maps.sphere import ideal_go_intensity
from raysim.optics.blockage import BLOCKED_SHARE
from raysim.scene.scene import parse_scene
from raysim.simulate import simulate
from raysim.surface.obstacles import Legs, leg_ends

F, D, R = 8.0, 20.0, 3.0
CABIN, WIDTH, FOOT, ROTATION = 1.5, 0.6, 8.0, 45.0
MARGIN = 2 * 0.15  # two ray spacings of the GO model's 0.15 m mesh
THETA_MAX, THETA_STEP, PHI_STEP = 60.0, 3.0, 5.0

OBSTACLES = f"""
[[obstacle]]
type = "disk"
radius_m = {CABIN}

[[obstacle]]
type = "legs"
count = 4
width_m = {WIDTH}
foot_radius_m = {FOOT}
apex_radius_m = {CABIN}
rotation_deg = {ROTATION}
"""

PLAN = f"""
[rig.track]
radius_m = {R}
[rig.limits]
slider_min_deg = -95.0
slider_max_deg = 95.0
rotation_min_deg = -5.0
rotation_max_deg = 185.0
[rig.park]
slider_deg = 95.0
[reflector]
focal_length_m = {F}
diameter_m = {D}
frequency_hz = 1.0e9
[grid]
theta_max_deg = {THETA_MAX}
theta_step_deg = {THETA_STEP}
phi_step_deg = {PHI_STEP}
[acquisition]
samples_per_point = 1
reference_samples = 1
reference_every_lines = 36
reference_theta_deg = 30.0
[simulator]
time_scale = 0.0
"""

SCENE = f"""
name = "blocked_small"
[dish]
diameter_m = {D}
focal_length_m = {F}
[[deformation]]
type = "bumps"
bumps = [{{x_m = 3.0, y_m = 2.0, amplitude_um = 300.0, sigma_m = 2.0}}]
[source]
frequency_hz = 1.0e9
[sphere]
radius_m = {R}
n_theta = {round(THETA_MAX / THETA_STEP)}
n_phi = {round(360 / PHI_STEP)}
theta_max_deg = {THETA_MAX}
"""


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """The plan with obstacles, the same plan without, and the scene of the same geometry."""
    ws = tmp_path_factory.mktemp("plan_obstacles")
    (ws / "plan.toml").write_text(PLAN + OBSTACLES)
    (ws / "plan_clear.toml").write_text(PLAN)
    fieldmaps.save(simulate(parse_scene(SCENE + OBSTACLES)), ws / "blocked.nc")
    fieldmaps.save(simulate(parse_scene(SCENE)), ws / "clear.nc")
    return ws


def _angular_gap(phi_lo: np.ndarray, phi_hi: np.ndarray, azimuth: float) -> np.ndarray:
    """Angle (rad) from ``azimuth`` to the nearest point of each interval [phi_lo, phi_hi]."""
    centre, half = 0.5 * (phi_lo + phi_hi), 0.5 * (phi_hi - phi_lo)
    off = np.abs(np.angle(np.exp(1j * (centre - azimuth))))
    return np.maximum(off - half, 0.0)


def test_the_plan_marks_the_cells_geometry_says(folder):
    plan = load_plan(folder / "plan.toml")
    blocked = plan.blocked_share > BLOCKED_SHARE
    g = plan.grid
    r = 2 * F * np.tan(g.theta_edges / 2)
    r_lo = np.repeat(r[:-1, None], g.n_phi, axis=1)
    r_hi = np.repeat(r[1:, None], g.n_phi, axis=1)
    phi_lo = np.repeat(g.phi_edges[None, :-1], g.n_theta, axis=0)
    phi_hi = np.repeat(g.phi_edges[None, 1:], g.n_theta, axis=0)
    # the cabin: the rows inside its radius are hidden
    assert np.all(blocked[r[1:] < CABIN - MARGIN])
    assert (r[1:] < CABIN - MARGIN).sum() >= 2
    legs = [math.radians(ROTATION) + k * math.pi / 2 for k in range(4)]
    # each leg's azimuth crosses a hidden cell at every radius between the cabin and the foot
    inside = (r_lo > CABIN + MARGIN) & (r_hi < FOOT - MARGIN)
    for azimuth in legs:
        on_leg = inside & (_angular_gap(phi_lo, phi_hi, azimuth) == 0.0)
        assert on_leg.sum() >= 10 and np.all(blocked[on_leg])
    # inside the feet, nothing off the legs' strips (half width w / sqrt(2) + margin) is hidden
    strip = np.zeros_like(blocked)
    for azimuth in legs:
        reach = np.arcsin(np.minimum((WIDTH / math.sqrt(2) + MARGIN) / np.maximum(r_lo, 1e-9), 1.0))
        strip |= _angular_gap(phi_lo, phi_hi, azimuth) < reach
    clear = (r_lo > CABIN + MARGIN) & (r_hi < FOOT) & ~strip
    assert clear.sum() > 200 and not np.any(blocked[clear])
    # beyond the feet the reflected rays cross the legs: cells there are hidden as well
    assert np.any(blocked[r_lo > FOOT])


def test_the_plans_marks_are_the_simulated_scenes(folder):
    plan = load_plan(folder / "plan.toml")
    field = fieldmaps.load(folder / "blocked.nc")
    assert np.array_equal(plan.blocked_share > BLOCKED_SHARE, field["blocked"].values.astype(bool))
    np.testing.assert_allclose(plan.blocked_share, field["blocked_share"].values, atol=1e-12)
    assert np.array_equal(plan.obstacle_mesh.vertices, field["obstacle_vertices"].values)
    feet, _ = leg_ends(Legs(4, WIDTH, FOOT, None, CABIN, math.radians(ROTATION)), F)
    assert np.allclose(np.hypot(feet[:, 0], feet[:, 1]), FOOT)


def test_a_scan_with_obstacles_carries_the_simulated_maps_marks(folder, tmp_path):
    plan = load_plan(folder / "plan.toml")
    field = fieldmaps.load(folder / "blocked.nc")
    measured = scan(plan, tmp_path / "scan.nc", simulate=folder / "blocked.nc").fieldmap
    blocked = measured["blocked"].values.astype(bool)
    assert np.array_equal(blocked, field["blocked"].values.astype(bool))
    assert measured.attrs["blocked_cells"] == field.attrs["blocked_cells"] == blocked.sum() > 0
    assert measured.attrs["obstacles"] == field.attrs["obstacles"]
    for name in ("obstacle_vertices", "obstacle_faces"):
        assert np.array_equal(measured[name].values, field[name].values)
    # the blocked ideal: the exact ideal times the share the obstacles leave
    theta = np.repeat(plan.grid.theta[:, None], plan.grid.n_phi, axis=1)
    exact = ideal_go_intensity(theta, F, R, D)
    share = field["blocked_share"].values
    np.testing.assert_allclose(measured["intensity_ideal"].values, exact * (1 - share), rtol=1e-12)
    # every cell is measured, blocked or not; a wholly hidden cell reads the shadow
    intensity = measured["intensity"].values
    assert np.all(np.isfinite(intensity))
    dark = share == 1.0
    assert dark.sum() > 20 and np.all(intensity[dark] < 1e-9)
    # a lit cell reads the simulated map's departure from its ideal (noise-free, at the centres)
    lit = ~blocked & (exact > 0)
    np.testing.assert_allclose(intensity[lit] / measured["intensity_ideal"].values[lit],
                               field["intensity"].values[lit] / field["intensity_ideal"].values[lit],
                               rtol=1e-6)
    # the inversion masks the blocked cells and models the obstacles
    from solver.invert import invert

    surface = invert(measured, N=32, refine_iterations=0)
    assert 0 < surface.attrs["samples_blocked"] <= blocked.sum()


def test_a_scan_refuses_a_map_whose_obstacles_are_not_the_plans(folder, tmp_path):
    with pytest.raises(PlanError, match="has obstacles in the beam .* the plan none"):
        scan(load_plan(folder / "plan_clear.toml"), tmp_path / "a.nc",
             simulate=folder / "blocked.nc")
    with pytest.raises(PlanError, match="has no obstacles in the beam"):
        scan(load_plan(folder / "plan.toml"), tmp_path / "b.nc", simulate=folder / "clear.nc")
    other = (folder / "plan.toml").read_text().replace(f"width_m = {WIDTH}", "width_m = 0.5")
    (tmp_path / "other.toml").write_text(other)
    with pytest.raises(PlanError, match="other obstacles in the beam"):
        scan(load_plan(tmp_path / "other.toml"), tmp_path / "c.nc", simulate=folder / "blocked.nc")


def test_obstacles_leave_the_journal_fingerprint_alone(folder):
    assert load_plan(folder / "plan.toml").fingerprint() == \
        load_plan(folder / "plan_clear.toml").fingerprint()


def test_an_obstacle_mesh_edited_between_two_reads_is_read_again(tmp_path):
    import os

    import trimesh

    def write_cabin(radius):
        trimesh.creation.cylinder(radius=radius, height=0.2).apply_translation(
            (0.0, 0.0, F)).export(tmp_path / "cabin.stl")

    write_cabin(1.0)
    (tmp_path / "plan.toml").write_text(PLAN + '\n[[obstacle]]\ntype = "mesh"\nfile = "cabin.stl"\n')
    first = load_plan(tmp_path / "plan.toml").obstacle_mesh
    write_cabin(2.0)
    stat = (tmp_path / "cabin.stl").stat()
    # an edit within the file system's time resolution still changes the stamp's size or time
    os.utime(tmp_path / "cabin.stl", ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))
    second = load_plan(tmp_path / "plan.toml").obstacle_mesh
    reach = [float(np.max(np.hypot(m.vertices[:, 0], m.vertices[:, 1]))) for m in (first, second)]
    assert reach[0] == pytest.approx(1.0, rel=1e-6) and reach[1] == pytest.approx(2.0, rel=1e-6)


@pytest.mark.parametrize(("reference", "drift", "refused"), [
    ((0.0, 0.0), "auto", "in the obstacles' shadow (100 %"),  # behind the cabin
    ((20.0, ROTATION), "linear", "in the obstacles' shadow"),  # along a leg
    ((80.0, 0.0), "auto", "beyond the rim image"),
    ((0.0, 0.0), "none", None),  # no drift correction: the reference only costs time
    ((30.0, 0.0), "auto", None),
])
def test_a_drift_reference_that_cannot_see_the_beam_is_refused(folder, reference, drift, refused):
    """The cabin hides theta < 2 atan(r_c / 2F) = 10.7 deg, a leg a strip along its azimuth:
    a reference there reads the receiver's floor, and drift corrections taken from it would
    scale every line by noise."""
    text = PLAN.replace("reference_theta_deg = 30.0", f"reference_theta_deg = {reference[0]}\n"
                        f"reference_phi_deg = {reference[1]}\ndrift_correction = \"{drift}\"")
    path = folder / f"plan_reference_{reference[0]:g}_{reference[1]:g}_{drift}.toml"
    path.write_text(text + OBSTACLES)
    if refused is None:
        load_plan(path)
    else:
        with pytest.raises(PlanError, match=re.escape(refused)):
            load_plan(path)
