"""The truth of a mesh scene is the mesh's own departure from its ideal, not zero.

A FieldMap of a scene whose dish is a mesh file used to get the scene's (absent) deformation
as its truth, so every map of it read as its own error ("RMS error 22 um, RRMS nan %")."""

import numpy as np
import pytest
import trimesh

from raysim.surface.mesh import paraboloid
from solver.invert import _truth_from_scene

D, F, A, SIGMA, X0 = 25.0, 7.5, 200e-6, 1.5, 4.0


def bump(x, y):
    """The deformation the test puts into the mesh (m along z), analytic."""
    return A * np.exp(-((x - X0) ** 2 + y ** 2) / (2 * SIGMA**2))


def _scene(tmp_path, with_ideal):
    dish = paraboloid(D, F, 0.25)
    v = dish.vertices.copy()
    trimesh.Trimesh(v, dish.faces, process=False).export(tmp_path / "ideal.ply")
    v[:, 2] += bump(v[:, 0], v[:, 1])
    trimesh.Trimesh(v, dish.faces, process=False).export(tmp_path / "dish.ply")
    ideal = f'ideal_mesh = "{tmp_path / "ideal.ply"}"\n' if with_ideal else ""
    return (f'name = "m"\n[dish]\nmesh = "{tmp_path / "dish.ply"}"\n{ideal}focal_length_m = {F}\n'
            "[source]\nfrequency_hz = 1e9\n[sphere]\nradius_m = 2.5\nn_theta = 18\nn_phi = 36\n")


def test_a_mesh_scenes_truth_is_its_departure_from_the_ideal(tmp_path):
    x = np.linspace(-0.45 * D, 0.45 * D, 61)
    X, Y = np.meshgrid(x, x)
    # without an ideal mesh the ideal is the paraboloid of F fitted through the vertices by
    # its vertex alone, which takes the bump's least-squares piston and tilts with it
    v = paraboloid(D, F, 0.25).vertices
    basis = np.column_stack([np.ones(len(v)), v[:, 0], v[:, 1]])
    plane, *_ = np.linalg.lstsq(basis, bump(v[:, 0], v[:, 1]), rcond=None)
    for with_ideal, expected in ((True, bump(X, Y)),
                                 (False, bump(X, Y) - plane[0] - plane[1] * X - plane[2] * Y)):
        truth = _truth_from_scene({"scene": _scene(tmp_path, with_ideal)})
        assert truth is not None
        # the files' surfaces over 0.25 m facets, on the dish (beyond the rim there is none):
        # 0.2 to 0.35 % of A measured, a tenth of the bump's curvature A / SIGMA^2 times h^2 / 8
        inside = np.hypot(X, Y) < 0.5 * D
        assert np.max(np.abs(truth(X, Y) - expected)[inside]) < 0.01 * A


def test_a_mesh_that_no_longer_loads_leaves_the_truth_unknown(tmp_path):
    text = _scene(tmp_path, True)
    (tmp_path / "dish.ply").unlink()
    assert _truth_from_scene({"scene": text}) is None


def test_simulate_states_how_far_a_mesh_departs_from_its_ideal(tmp_path):
    """The FieldMap and the summary line carry the mesh's RMS departure along z, the figure
    that shows a file not in the reflector frame (a tilted axis reads as coma)."""
    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate, summary

    ds = simulate(parse_scene(_scene(tmp_path, True)), method="go")
    v = paraboloid(D, F, 0.25).vertices
    expected = float(np.sqrt(np.mean(bump(v[:, 0], v[:, 1]) ** 2)))
    assert ds.attrs["mesh_departure_rms_m"] == pytest.approx(expected, rel=1e-3)  # float32 file
    assert "um RMS along z from its ideal" in summary(ds)


def test_the_truth_of_a_mesh_scene_is_found_from_any_folder_and_only_for_its_own_file(tmp_path, monkeypatch):
    """The scene's relative mesh names were resolved in the folder invert ran in: there the
    truth was unknown, and elsewhere another file of the same name became the truth."""
    from raysim.scene.scene import load_scene
    from raysim.simulate import simulate
    from solver.aperture import ApertureGrid
    from solver.invert import truth_on_grid
    from solver.linear import Scan

    project = tmp_path / "project"
    (project / "scenes").mkdir(parents=True)
    text = _scene(project / "scenes", True).replace(str(project / "scenes") + "/", "")
    (project / "scenes" / "s.toml").write_text(text)   # names dish.ply and ideal.ply beside it
    field = simulate(load_scene(project / "scenes" / "s.toml"), method="go")
    grid = ApertureGrid(D, 33)
    X, Y = grid.XY
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    got = truth_on_grid("scene", Scan.from_fieldmap(field), grid)
    assert got is not None and np.nanmax(np.abs(got - grid.masked(bump(X, Y)))) < 0.01 * A
    # another dish under the same names where the scene's folder was: not this map's truth
    other = paraboloid(D, F, 0.25)
    trimesh.Trimesh(other.vertices, other.faces, process=False).export(project / "scenes" / "dish.ply")
    assert truth_on_grid("scene", Scan.from_fieldmap(field), grid) is None


def test_a_dish_mesh_in_millimetres_read_as_metres_is_warned_of(tmp_path):
    """A 0.8 m dish exported in millimetres loads, with the default unit of 1 m, as an 800 m
    dish (inside the 1 000 m a file may span): the run says so and names the key to set."""
    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate, summary

    small = paraboloid(0.8, 0.32, 0.04)
    trimesh.Trimesh(small.vertices * 1000.0, small.faces, process=False).export(tmp_path / "mm.ply")
    text = (f'name = "mm"\n[dish]\nmesh = "{tmp_path / "mm.ply"}"\n'
            "[source]\nfrequency_hz = 1e9\n[sphere]\nradius_m = 100.0\nn_theta = 9\nn_phi = 18\n")
    line = summary(simulate(parse_scene(text), method="go"))
    assert "the mesh's dish is 800 m across" in line and "dish.mesh_unit_m = 0.001" in line
    # in metres, and at 100 GHz, where GO holds on a 0.8 m dish (267 wavelengths; the sphere
    # 83 focal-spot widths): no warning of any kind
    metres = (text.replace("[source]", "mesh_unit_m = 0.001\n[source]").replace("100.0", "0.1")
              .replace("1e9", "1e11"))
    assert "WARNING" not in summary(simulate(parse_scene(metres), method="go"))


def test_nodes_that_slid_along_the_surface_are_no_deformation(tmp_path):
    """An FEM output moves nodes sideways too: here every node of the deformed file slid up to
    5 mm along the paraboloid itself, so the surface did not change. Heights compared at one
    (x, y) say so; z compared vertex by vertex read it as 2.1 mm RMS of deformation."""
    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate

    dish = paraboloid(D, F, 0.25)
    v = dish.vertices.copy()
    trimesh.Trimesh(v, dish.faces, process=False).export(tmp_path / "ideal.ply")
    v[:, 0] += 5e-3 * np.sin(v[:, 1] / 2.0)
    v[:, 1] += 5e-3 * np.cos(v[:, 0] / 3.0)
    v[:, 2] = (v[:, 0] ** 2 + v[:, 1] ** 2) / (4 * F)
    trimesh.Trimesh(v, dish.faces, process=False).export(tmp_path / "dish.ply")
    text = (f'name = "m"\n[dish]\nmesh = "{tmp_path / "dish.ply"}"\nideal_mesh = "{tmp_path / "ideal.ply"}"\n'
            f"focal_length_m = {F}\n[source]\nfrequency_hz = 1e9\n[sphere]\nradius_m = 2.5\n"
            "n_theta = 18\nn_phi = 36\n")
    ds = simulate(parse_scene(text), method="go")
    assert ds.attrs["mesh_departure_rms_m"] < 1e-6  # the float32 files' rounding
    truth = _truth_from_scene({"scene": text, "mesh_departure_rms_m": ds.attrs["mesh_departure_rms_m"]})
    x = np.linspace(-0.45 * D, 0.45 * D, 41)
    X, Y = np.meshgrid(x, x)
    inside = np.hypot(X, Y) < 0.5 * D
    assert np.max(np.abs(truth(X, Y))[inside]) < 2e-6
