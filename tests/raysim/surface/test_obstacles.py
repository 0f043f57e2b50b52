"""The built-in obstacles' triangles and the scene's [[obstacle]] tables."""

from __future__ import annotations

import math

import numpy as np
import pytest

from raysim.scene.scene import parse_scene
from raysim.surface.obstacles import Disk, Legs, disk_triangles, leg_ends, leg_triangles, obstacle_mesh

F = 8.0


def test_the_disk_polygon_covers_its_radius_and_no_more_than_its_sag():
    v, f = disk_triangles(Disk(2.0, 5.0))
    assert np.all(v[:, 2] == 5.0)
    rim = np.hypot(v[1:, 0], v[1:, 1])
    # the inscribed circle of the polygon is the disk: edge midpoints at the radius
    mid = 0.5 * (v[f[:, 1]] + v[f[:, 2]])
    assert np.allclose(np.hypot(mid[:, 0], mid[:, 1]), 2.0)
    assert rim.max() < 2.0 / math.cos(math.pi / 100)


def test_a_leg_is_a_box_width_square_about_its_centre_line():
    legs = Legs(3, 0.4, 7.0, None, 1.0, math.radians(30))
    v, f = leg_triangles(legs, F)
    feet, apexes = leg_ends(legs, F)
    assert len(f) == 36 and len(v) == 24
    assert np.allclose(feet[:, 2], 49.0 / (4 * F)) and np.allclose(apexes[:, 2], F)  # on the dish, up to the focus
    assert np.allclose(np.degrees(np.arctan2(feet[:, 1], feet[:, 0])), [30, 150, -90])
    for k in range(3):
        a, b = feet[k], apexes[k]
        axis = (b - a) / np.linalg.norm(b - a)
        corners = v[8 * k: 8 * k + 8]
        rel = corners - a
        off = rel - np.outer(rel @ axis, axis)
        assert np.allclose(np.linalg.norm(off, axis=1), 0.4 / math.sqrt(2))  # square cross-section
        # the faces close the box: every edge is shared by two triangles
        edges = np.sort(np.concatenate([f[12 * k:12 * k + 12][:, [0, 1]], f[12 * k:12 * k + 12][:, [1, 2]],
                                        f[12 * k:12 * k + 12][:, [2, 0]]]), axis=1)
        _, count = np.unique(edges, axis=0, return_counts=True)
        assert np.all(count == 2)


def test_scene_obstacle_tables_become_specs_in_si_units():
    scene = parse_scene("""
[dish]
diameter_m = 20.0
focal_length_m = 8.0
[[obstacle]]
type = "disk"
radius_m = 1.5
[[obstacle]]
type = "legs"
count = 4
width_m = 0.3
foot_radius_m = 7.0
rotation_deg = 45.0
[source]
frequency_hz = 1e9
[sphere]
radius_m = 3.0
""")
    disk, legs = scene.obstacles
    assert disk == Disk(1.5, 8.0)  # at the focus height unless z_m says otherwise
    assert legs.count == 4 and legs.apex_z is None and legs.rotation == pytest.approx(math.pi / 4)
    mesh = obstacle_mesh(scene.obstacles, scene.F)
    assert len(mesh.faces) == 128 + 4 * 12 and mesh == obstacle_mesh(scene.obstacles, scene.F)
    assert "4 legs 0.3 m wide" in mesh.description
