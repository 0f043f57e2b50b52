"""Obstacles in the beam: the GO FieldMap's shadows where plain geometry puts them.

The reference is computed here a second way, without rays or meshes: each sphere cell is
sampled at sub-cell points (theta, phi), each mapped to its aperture point by the ideal
mapping r = 2F tan(theta/2) and to its point p on the paraboloid. The incident ray to p is the
vertical line through it; the reflected ray runs from p towards the focus and stops at the
sphere. A leg is its centre line, a cylinder of radius width/2 inside the square box and
width/sqrt(2) around it; the cabin a disk at the focus height. Cells the inner shapes hide
(with a margin for the ray tubes' size) must be marked blocked; cells the outer shapes miss by
the margin must not be.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from raysim.scene.scene import parse_scene
from raysim.simulate import simulate
from raysim.surface.obstacles import Legs, leg_ends

F, D, R = 8.0, 20.0, 3.0
RESOLUTION = 0.05
CABIN, WIDTH, FOOT, APEX_R, ROTATION = 0.8, 0.3, 7.0, 0.8, 45.0
MARGIN = 2.0 * RESOLUTION  # a tube a shadow crosses spreads what passes over its whole footprint
SUB = 6  # sub-cell samples per cell edge

SCENE = f"""
name = "quadripod"
[dish]
diameter_m = {D}
focal_length_m = {F}
resolution_m = {RESOLUTION}
[[deformation]]
type = "bumps"
bumps = [{{x_m = 3.0, y_m = 2.0, amplitude_um = 300.0, sigma_m = 2.0}}]
{{obstacles}}
[source]
frequency_hz = 1.0e9
[sphere]
radius_m = {R}
n_theta = 45
n_phi = 180
"""
CABIN_TABLE = f"""
[[obstacle]]
type = "disk"
radius_m = {CABIN}
"""
LEGS_TABLE = f"""
[[obstacle]]
type = "legs"
count = 4
width_m = {WIDTH}
foot_radius_m = {FOOT}
apex_radius_m = {APEX_R}
rotation_deg = {ROTATION}
"""


@pytest.fixture(scope="module")
def blocked_map():
    return simulate(parse_scene(SCENE.replace("{obstacles}", CABIN_TABLE + LEGS_TABLE)))


def _segments_distance(p0, p1, q0, q1) -> np.ndarray:
    """Distance (m) between the segments p0-p1 (..., 3) and q0-q1 (3,): the closest pair of
    points, parameters clamped to the segments (Lumelsky's construction)."""
    u, v, w0 = p1 - p0, q1 - q0, p0 - q0
    a, b, c = np.sum(u * u, -1), np.sum(u * v, -1), float(v @ v)
    d, e = np.sum(u * w0, -1), np.sum(v * w0, -1)
    den = a * c - b * b
    s = np.clip(np.where(den > 1e-12, (b * e - c * d) / np.where(den > 1e-12, den, 1.0), 0.0), 0, 1)
    t = (b * s + e) / c
    s = np.where(t < 0, np.clip(-d / a, 0, 1), np.where(t > 1, np.clip((b - d) / a, 0, 1), s))
    t = np.clip(t, 0, 1)
    return np.linalg.norm(w0 + s[..., None] * u - t[..., None] * v, axis=-1)


def _reference(grid, radius_legs: float, radius_cabin: float):
    """Per cell: the share of sub-cell samples a cylinder of ``radius_legs`` about each leg's
    centre line hides on the incident or the reflected leg, or a cabin of ``radius_cabin`` on
    the incident leg (the reflected rays end on the sphere before they reach the focus
    height); and the share hidden on the reflected leg alone."""
    sub = (np.arange(SUB) + 0.5) / SUB
    theta = (grid.theta_edges[:-1, None] + sub[None, :] * grid.dtheta).ravel()
    phi = (grid.phi_edges[:-1, None] + sub[None, :] * grid.dphi).ravel()
    t, p = np.meshgrid(theta, phi, indexing="ij")
    r = 2 * F * np.tan(t / 2)
    dish = np.stack([r * np.cos(p), r * np.sin(p), r * r / (4 * F)], axis=-1)
    focus = np.array([0.0, 0.0, F])
    u = (dish - focus) / np.linalg.norm(dish - focus, axis=-1, keepdims=True)
    entry = focus + R * u  # where the ray reflected at p towards the focus meets the sphere
    above = dish + np.array([0.0, 0.0, 100.0])  # the incident ray comes straight down to p
    feet, apexes = leg_ends(Legs(4, WIDTH, FOOT, None, APEX_R, math.radians(ROTATION)), F)
    incident = r < radius_cabin
    reflected = np.zeros_like(incident)
    for a, b in zip(feet, apexes, strict=True):
        incident |= _segments_distance(dish, above, a, b) < radius_legs
        reflected |= _segments_distance(dish, entry, a, b) < radius_legs
    shape = (grid.n_theta, SUB, grid.n_phi, SUB)
    hidden = (incident | reflected).reshape(shape).mean(axis=(1, 3))
    out_only = (reflected & ~incident).reshape(shape).mean(axis=(1, 3))
    return hidden, out_only


def test_quadripod_and_cabin_shadows_lie_where_geometry_puts_them(blocked_map):
    from raysim.maps.fieldmap import grid_of

    grid = grid_of(blocked_map)
    blocked = blocked_map["blocked"].values.astype(bool)
    inner, out_only = _reference(grid, WIDTH / 2 - MARGIN, CABIN - MARGIN)
    outer, _ = _reference(grid, WIDTH / math.sqrt(2) + MARGIN, CABIN + MARGIN)
    # every cell a shadow surely reaches is marked, and nothing the shadows surely miss
    assert inner.astype(bool).sum() > 400
    assert np.all(blocked[inner > 0])
    assert not np.any(blocked[outer == 0])
    # the reflected rays' own shadow (beyond the feet) is there and marked
    assert (out_only > 0).sum() >= 8 and np.all(blocked[(out_only > 0) & (inner > 0)])
    # wholly hidden cells receive no power, from the deformed dish or the ideal one
    dark = inner == 1.0
    assert dark.sum() > 100
    assert np.all(blocked_map["intensity"].values[dark] == 0.0)
    assert np.all(blocked_map["intensity_ideal"].values[dark] == 0.0)
    # the blocked share is a share, and the wholly hidden cells lost all of their power
    share = blocked_map["blocked_share"].values
    assert share.min() >= 0.0 and share.max() <= 1.0 + 1e-12
    assert np.all(share[dark] == pytest.approx(1.0))


def test_a_cabin_at_the_focus_hides_the_aperture_centre(blocked_map):
    from raysim.maps.fieldmap import grid_of

    grid = grid_of(blocked_map)
    blocked = blocked_map["blocked"].values.astype(bool)
    theta_c = 2 * math.atan(CABIN / (2 * F))   # r = 2F tan(theta/2) at the cabin's rim
    inside = grid.theta_edges[1:] < 2 * math.atan((CABIN - MARGIN) / (2 * F))
    assert inside.sum() >= 2 and np.all(blocked[inside])
    assert np.all(blocked_map["intensity_ideal"].values[inside] == 0.0)
    # just beyond the cabin the rows are lit again, apart from the legs
    beyond = (grid.theta_edges[:-1] > 2 * math.atan((CABIN + MARGIN) / (2 * F))) & (
        grid.theta_edges[:-1] < theta_c + math.radians(10))
    assert beyond.any() and np.all(blocked[beyond].mean(axis=1) < 0.3)
    assert blocked_map.attrs["blocked_cells"] == int(blocked.sum())
    assert "disk r=0.8 m" in blocked_map.attrs["obstacles"]


def test_no_obstacle_leaves_the_fieldmap_as_it_was():
    clear = simulate(parse_scene(SCENE.replace("{obstacles}", "")))
    assert not {"blocked", "blocked_share", "obstacle_vertices", "obstacle_faces"} & set(clear.data_vars)
    assert not {"obstacles", "blocked_cells", "blocked_threshold", "blocked_rays"} & set(clear.attrs)
    # a small disk high above the vertex shades the centre only: every other cell keeps the
    # clear dish's intensities bit for bit
    high = simulate(parse_scene(SCENE.replace("{obstacles}", f"""
[[obstacle]]
type = "disk"
radius_m = 0.5
z_m = {3 * F}
""")))
    lit = ~high["blocked"].values.astype(bool)
    assert 0.95 * lit.size < lit.sum() < lit.size
    assert np.array_equal(high["intensity"].values[lit], clear["intensity"].values[lit])
    assert np.array_equal(high["intensity_ideal"].values[lit], clear["intensity_ideal"].values[lit])


@pytest.mark.parametrize("resolution", [0.2, 0.1])
def test_a_disk_at_the_focus_blocks_its_own_area_whatever_the_mesh(resolution):
    """QA: a 1 m disk at the focus of a 10 m dish (F = 4 m) took 3.80 m^2 of the aperture's
    power on 0.1 m triangles, 4.52 on 0.2 m, where geometry says pi r^2 = 3.14 (on the way in
    it shades a disk of its radius; on the way out every ray stops at the sphere, 2 m short of
    the focus and the disk): a tube with one blocked ray was dropped whole, a tube's width
    along the whole edge. The tubes a shadow's edge crosses now keep the share of their sub-rays
    that pass."""
    text = f"""name = "cabin"
[dish]
diameter_m = 10.0
focal_length_m = 4.0
resolution_m = {resolution}
[source]
frequency_hz = 1e9
[sphere]
radius_m = 2.0
n_theta = 45
n_phi = 72
"""
    clear = simulate(parse_scene(text))
    cabin = simulate(parse_scene(text + '[[obstacle]]\ntype = "disk"\nradius_m = 1.0\nz_m = 4.0\n'))
    taken = clear.attrs["lit_area"] - cabin.attrs["lit_area"]
    assert taken == pytest.approx(math.pi, rel=0.01)
    assert cabin.attrs["power_on_sphere"] == pytest.approx(cabin.attrs["lit_area"], rel=1e-9)
