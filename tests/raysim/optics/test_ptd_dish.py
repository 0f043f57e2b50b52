"""Edges of a dish (rim and panel gaps) and the fringe field's symmetry; PO + PTD through simulate.

Geometry checks are independent of the edge code: the rim is the circle of circumference
pi D on the paraboloid; a point just inside an edge lies on its panel and a point just
outside lies in the gap (the panel layout's own point location). The field checks use the
dish's mirror symmetry: the paraboloid and its panels (phi0 = 0) are unchanged by y -> -y,
and so is the x-polarised incident wave travelling along -z, so the scattered field obeys
E_x(x, -y, z) = E_x(x, y, z), E_y(x, -y, z) = -E_y(x, y, z), E_z(x, -y, z) = E_z(x, y, z).
Nothing in the edge code enforces this: edges are found, oriented and framed from the mesh,
whose triangles the mirror maps to differently wound ones.
"""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from raysim.errors import RaysimError
from raysim.maps.fieldmap import load
from raysim.maps.sphere import SphereGrid
from raysim.optics import po, ptd
from raysim.scene.scene import parse_scene
from raysim.simulate import simulate
from raysim.surface.edges import edge_quadrature
from raysim.surface.mesh import paraboloid
from raysim.surface.panels import PanelLayout
from tests.cli import run_cli

D, F = 12.0, 4.8  # a small dish, 12 wavelengths across at 0.3 GHz (m)
GAP = 0.010
LAYOUT = PanelLayout((0.0, 2.0, 4.0, 6.0), (4, 8, 12), GAP)

SCENE = f"""
name = "small_ptd"
[dish]
diameter_m = {D}
focal_length_m = {F}
resolution_m = 1.0
[panels]
ring_edges_m = [0.0, 2.0, 4.0, 6.0]
panels_per_ring = [4, 8, 12]
gap_m = {GAP}
[source]
frequency_hz = 0.3e9
[sphere]
radius_m = 2.0
n_theta = 6
n_phi = 8
"""


def test_rim_is_the_true_circle():
    dish = paraboloid(110.0, 33.0, 5.0)
    rim = edge_quadrature(dish, 1.0, "rim")
    assert np.sum(rim.length) == pytest.approx(np.pi * 110.0, rel=1e-12)
    r = np.hypot(rim.points[:, 0], rim.points[:, 1])
    assert np.allclose(r, 55.0, rtol=1e-12)
    assert np.allclose(rim.points[:, 2], 55.0**2 / (4 * 33.0), rtol=1e-12)
    # tangent along phi, inward in the surface towards the axis, normal towards +z
    phi_hat = np.column_stack([-rim.points[:, 1], rim.points[:, 0], 0 * r]) / r[:, None]
    assert np.allclose(np.abs(np.sum(rim.tangent * phi_hat, axis=1)), 1.0, atol=1e-12)
    assert np.all(np.sum(rim.inward * rim.points, axis=1) < 0)
    assert np.allclose(np.sum(rim.inward * rim.normal, axis=1), 0.0, atol=1e-12)
    assert np.all(rim.normal[:, 2] > 0)
    # every free edge of the one-piece dish is on the rim
    assert len(edge_quadrature(dish, 1.0, "all")) == len(rim)


def test_panel_edges_face_their_panel_and_the_gap():
    dish = paraboloid(D, F, 1.0, LAYOUT)
    edges = edge_quadrature(dish, 0.25, "all")
    assert 0 < edges.rim.sum() < len(edges)
    panel = dish.face_panel[edges.face]
    step = 0.25 * GAP
    inside = edges.points + step * edges.inward
    outside = edges.points - step * edges.inward
    assert np.array_equal(LAYOUT.panel_at(inside[:, 0], inside[:, 1]), panel)
    gap_side = LAYOUT.panel_at(outside[:, 0], outside[:, 1])
    beyond_rim = np.hypot(outside[:, 0], outside[:, 1]) > D / 2
    assert np.all((gap_side == -1) | beyond_rim)
    assert np.array_equal(beyond_rim, edges.rim)
    # points on the panel's smooth surface, frames orthonormal
    assert np.allclose(edges.points[:, 2], dish.surface.height(edges.points[:, 0], edges.points[:, 1]),
                       atol=1e-12)
    frame = np.stack([edges.tangent, edges.inward, edges.normal], axis=1)
    assert np.allclose(frame @ frame.transpose(0, 2, 1), np.eye(3), atol=1e-12)
    # the rim set is the rim part of the full set
    assert len(edge_quadrature(dish, 0.25, "rim")) == edges.rim.sum()


def mirrored(E: np.ndarray) -> np.ndarray:
    """The y -> -y image of a field on a grid whose phi cells are symmetric about phi = 0."""
    image = E[:, ::-1].copy()
    image[..., 1] *= -1.0
    return image


@pytest.mark.parametrize("edges", ["rim", "all"])
def test_fringe_field_is_mirror_symmetric(edges):
    dish = paraboloid(D, F, 1.0, LAYOUT)
    grid = SphereGrid(2.0, 7, 16)
    wave = po.Illumination.plane_wave(0.3e9, (0, 0, -1), (1, 0, 0))
    E = ptd.sphere_edge_field(dish, grid, wave, edges).E
    scale = np.abs(E).max()
    assert scale > 1e-3  # the edges do radiate
    assert np.abs(E - mirrored(E)).max() < 1e-10 * scale
    # and the field is not trivially symmetric component by component
    assert np.abs(E[..., 1]).max() > 1e-3 * scale


def test_simulate_adds_the_edges_to_po():
    """The po+ptd FieldMap holds, for each reflector, the PO field of its surface plus the
    fringe field of its edges, each as the engine computes it on its own."""
    from raysim.surface.mesh import reflectors_for

    scene = parse_scene(SCENE)
    both = simulate(scene, method="po+ptd", edges="all", save_field=True)
    assert both.attrs["method"] == "po+ptd" and both.attrs["edges"] == "all"
    assert both.attrs["edge_points_lit"] == both.attrs["edge_points"] > 0

    def field(ds, name):
        return ds[f"{name}_re"].values + 1j * ds[f"{name}_im"].values

    wave = po.Illumination.plane_wave(scene.source.frequency_hz, scene.source.direction, scene.source.e_hat)
    ideal, deformed = reflectors_for(scene)
    for name, reflector in (("E", deformed), ("E_ideal", ideal)):
        surface = po.sphere_field(reflector, scene.sphere, wave, po.DEFAULT_SAMPLES_PER_WAVELENGTH).E
        edges = ptd.sphere_edge_field(reflector, scene.sphere, wave, "all").E
        assert np.abs(field(both, name.replace("E", "E_edges")) - edges).max() < 1e-12
        assert np.abs(field(both, name) - surface - edges).max() < 1e-12
        assert np.abs(edges).max() > 1e-4 * np.abs(surface).max()
    rim_only = simulate(replace(scene), method="po+ptd")
    assert both.attrs["edge_gap_wavelengths"] == pytest.approx(GAP / (po.C0 / 0.3e9))
    assert rim_only.attrs["edges"] == "rim" and "edge_gap_wavelengths" not in rim_only.attrs
    assert rim_only.attrs["edge_points"] < both.attrs["edge_points"]
    # gaps far below a wavelength: the line a user reads warns that the edge model overstates them
    from raysim.simulate import summary

    assert GAP / (po.C0 / 0.3e9) < 1.0
    assert "overstates gaps narrower than a wavelength" in summary(both)
    assert "overstates" not in summary(rim_only)


@pytest.mark.parametrize(("method", "edges", "message"), [
    ("po", "all", "--edges applies to --method po+ptd only"),
    ("po+ptd", "gaps", "unknown edge set 'gaps'"),
])
def test_edge_options_are_checked_before_any_work(method, edges, message):
    with pytest.raises(RaysimError, match=re.escape(message)):
        simulate(parse_scene(SCENE), method=method, edges=edges)


def test_cli_edges(tmp_path):
    scene = tmp_path / "small.toml"
    scene.write_text(SCENE.replace("n_theta = 6", "n_theta = 3").replace("n_phi = 8", "n_phi = 4"))
    run = run_cli("simulate", str(scene), "-o", "x.nc", "--method", "po+ptd", "--edges", "all",
                     cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "all edges (" in run.stdout
    ds = load(tmp_path / "x.nc")
    assert ds.attrs["method"] == "po+ptd" and ds.attrs["edges"] == "all"
    bad = run_cli("simulate", str(scene), "-o", "y.nc", "--edges", "all", cwd=tmp_path)
    assert bad.returncode == 2 and "--edges applies to --method po+ptd only" in bad.stderr
    assert not (tmp_path / "y.nc").exists()
