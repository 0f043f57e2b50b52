"""Panels and meshes: exact footprint areas, no triangle across a gap, smooth normals, files."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import shapely
from shapely.geometry import LineString, Point

from raysim.errors import MeshError
from raysim.surface.deformation import GaussianBumps, PanelRigid
from raysim.surface.mesh import (
    fit_paraboloid,
    load_reflector,
    mesh_departure_rms,
    paraboloid,
    unit_normals,
)
from raysim.surface.panels import PanelLayout

D, F = 110.0, 33.0
LAYOUT = PanelLayout((0.0, 6.875, 13.75, 27.5, 55.0), (6, 12, 24, 36), 0.01)


def shapely_panel(layout: PanelLayout, panel: int):
    """The panel's footprint built independently: an annular sector minus buffered cut lines."""
    ring = int(layout.ring(panel))
    a, b = layout.ring_edges[ring], layout.ring_edges[ring + 1]
    phi_a, phi_b = layout.angular_limits(panel)
    phi = np.linspace(phi_a, phi_b, 4000)
    outer = np.column_stack([b * np.cos(phi), b * np.sin(phi)])
    inner = np.column_stack([a * np.cos(phi[::-1]), a * np.sin(phi[::-1])]) if a > 0 else np.zeros((1, 2))
    sector = shapely.Polygon(np.vstack([outer, inner]))
    cuts = [LineString([(0, 0), (70 * np.cos(p), 70 * np.sin(p))]) for p in (phi_a, phi_b)]
    half = layout.gap / 2
    removed = shapely.union_all([c.buffer(half, cap_style="flat") for c in cuts])
    if ring > 0:
        removed = removed.union(Point(0, 0).buffer(a + half, 4000).difference(Point(0, 0).buffer(a - half, 4000)))
    if ring < layout.n_rings - 1:
        removed = removed.union(Point(0, 0).buffer(b + half, 4000).difference(Point(0, 0).buffer(b - half, 4000)))
    return sector.difference(removed)


@pytest.mark.parametrize("panel", [0, 3, 6, 17, 40, 77])
def test_panel_area_matches_an_independent_polygon(panel):
    assert LAYOUT.panel_area(panel) == pytest.approx(shapely_panel(LAYOUT, panel).area, rel=2e-5)


def test_panel_at_agrees_with_the_independent_polygons():
    rng = np.random.default_rng(4)
    x, y = rng.uniform(-56, 56, 3000), rng.uniform(-56, 56, 3000)
    ids = LAYOUT.panel_at(x, y)
    for panel in (3, 17, 40):
        poly = shapely_panel(LAYOUT, panel)
        inside = shapely.contains_xy(poly, x, y)
        # points within 1 mm of an edge may fall either way (the polygon's arcs are chords)
        far = shapely.distance(poly.boundary, shapely.points(x, y)) > 1e-3
        assert np.array_equal(inside[far], (ids == panel)[far])


def test_mesh_covers_the_aperture():
    r = paraboloid(D, F, 0.3)
    # a disk of radius a triangulated with n rim chords lacks a^2 (n/2 sin(2 pi/n) - pi)
    n_rim = np.sum(np.isclose(np.hypot(r.vertices[:, 0], r.vertices[:, 1]), D / 2))
    polygon = 0.5 * n_rim * (D / 2) ** 2 * np.sin(2 * np.pi / n_rim)
    assert r.projected_area() == pytest.approx(polygon, rel=1e-12)
    assert r.mesh.euler_number == 1  # one disk, no holes


def test_paraboloid_vertices_and_normals_are_exact():
    r = paraboloid(D, F, 0.5)
    x, y, z = r.vertices.T
    assert np.allclose(z, (x * x + y * y) / (4 * F), rtol=0, atol=1e-12)
    analytic = np.column_stack([-x / (2 * F), -y / (2 * F), np.ones_like(x)])
    analytic /= np.linalg.norm(analytic, axis=1, keepdims=True)
    assert np.abs(r.vertex_normals - analytic).max() < 1e-14
    # faces are wound so their normals point into the dish, towards the focus
    assert np.all(r.mesh.face_normals[:, 2] > 0)


def test_panels_own_their_vertices_and_no_face_crosses_a_gap():
    r = paraboloid(D, F, 0.4, LAYOUT)
    assert r.n_panels == LAYOUT.n_panels
    # each vertex belongs to the faces of a single panel
    owners = np.full(len(r.vertices), -1)
    for k in range(3):
        owners[r.faces[:, k]] = r.face_panel
    for k in range(3):
        assert np.array_equal(owners[r.faces[:, k]], r.face_panel)
    # every face lies on its panel: its centroid is on that panel, and no edge spans a gap
    c = r.vertices[r.faces].mean(axis=1)
    assert np.array_equal(LAYOUT.panel_at(c[:, 0], c[:, 1]), r.face_panel)
    # mesh footprint area = exact panel area up to the chords of the arcs
    exact = sum(LAYOUT.panel_area(p) for p in range(LAYOUT.n_panels))
    assert r.projected_area() == pytest.approx(exact, rel=1e-4)


def test_normals_are_smooth_within_a_panel_and_jump_across_a_gap():
    rng = np.random.default_rng(5)
    n = LAYOUT.n_panels
    tilt = PanelRigid(LAYOUT, np.zeros(n), rng.normal(0, 1e-3, n), rng.normal(0, 1e-3, n))
    ideal = paraboloid(D, F, 0.4, LAYOUT)
    bent = ideal.deformed(tilt)
    # same triangulation, vertices moved along z only
    assert np.array_equal(bent.faces, ideal.faces)
    assert np.array_equal(bent.vertices[:, :2], ideal.vertices[:, :2])
    # each panel's normals are the ideal ones tilted by that panel's slope (no averaging)
    x, y = ideal.vertices[:, 0], ideal.vertices[:, 1]
    k = ideal.vertex_panel
    expect = np.column_stack([-(x / (2 * F) + tilt.tilt_x[k]), -(y / (2 * F) + tilt.tilt_y[k]), np.ones_like(x)])
    expect /= np.linalg.norm(expect, axis=1, keepdims=True)
    assert np.abs(bent.vertex_normals - expect).max() < 1e-14


def test_unit_normals_are_the_normalised_stack_bit_for_bit():
    # the component-wise normals are what n / |n| of the stacked (-gx, -gy, 1) gives, to the
    # bit: random slopes of every scale, signed zeros, infinities, NaNs, huge and tiny values
    rng = np.random.default_rng(5)
    special = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, -np.nan, 1e300, -1e-300, 1e154])
    sx, sy = np.meshgrid(special, special)
    gx = np.concatenate([sx.ravel(), *(rng.normal(0, s, 100_000) for s in (1e-7, 1e-3, 0.5, 40.0))])
    gy = np.concatenate([sy.ravel(), *(rng.normal(0, s, 100_000) for s in (1e-7, 1e-3, 0.5, 40.0))])
    with np.errstate(invalid="ignore", over="ignore"):
        n = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
        expected = n / np.linalg.norm(n, axis=-1, keepdims=True)
        got = unit_normals(gx, gy)
        assert got.tobytes() == expected.tobytes()
        assert unit_normals(gx[:12].reshape(3, 4), gy[:12].reshape(3, 4)).tobytes() == expected[:12].tobytes()
    assert unit_normals(0.3, -0.2).shape == (3,)


def test_deformed_mesh_moves_vertices_by_delta():
    bump = GaussianBumps(((5.0, 5.0, 1e-3, 3.0),))
    ideal = paraboloid(D, F, 0.5)
    bent = ideal.deformed(bump)
    x, y = ideal.vertices[:, 0], ideal.vertices[:, 1]
    assert np.allclose(bent.vertices[:, 2] - ideal.vertices[:, 2], bump(x, y), rtol=0, atol=1e-15)


@pytest.mark.parametrize("suffix", [".stl", ".ply", ".obj", ".glb"])
def test_loaded_mesh_recovers_the_paraboloid(tmp_path: Path, suffix: str):
    bump = GaussianBumps(((10.0, -8.0, 2e-3, 4.0),))
    source = paraboloid(20.0, 8.0, 0.5, PanelLayout((0.0, 4.0, 10.0), (1, 8), 0.05)).deformed(bump)
    shifted = source.mesh.copy()
    shifted.apply_translation([0.3, -0.2, 1.5])  # not in the reflector frame
    shifted.apply_scale(1000.0)  # written in millimetres
    path = tmp_path / f"dish{suffix}"
    shifted.export(path)
    ideal, loaded, fit = load_reflector(path, unit=1e-3, F=8.0)
    assert loaded.n_panels == 9  # the connected pieces: a central disk and eight panels
    assert len(loaded.faces) == len(source.faces)
    # with F known the fit finds the vertex: the loaded surface error is the bump less its
    # least-squares piston and tilts (computed here independently), to within float32 storage
    xs, ys = source.vertices[:, 0], source.vertices[:, 1]
    A = np.column_stack([np.ones_like(xs), xs, ys])
    coef, *_ = np.linalg.lstsq(A, bump(xs, ys), rcond=None)
    residual = bump(xs, ys) - A @ coef
    dz = loaded.vertices[:, 2] - ideal.vertices[:, 2]
    from scipy.spatial import cKDTree

    moved = loaded.vertices[:, :2] + [fit.x0 - 0.3, fit.y0 + 0.2]
    distance, match = cKDTree(source.vertices[:, :2]).query(moved)
    assert distance.max() < 1e-3
    assert np.abs(dz - residual[match]).max() < 5e-6
    assert fit.F == 8.0 and (fit.x0, fit.y0) == pytest.approx((0.3, -0.2), abs=2e-3)
    assert np.array_equal(ideal.faces, loaded.faces)
    assert np.all(loaded.mesh.face_normals[:, 2] > 0)


def test_fit_paraboloid_finds_focal_length_and_vertex():
    rng = np.random.default_rng(6)
    x, y = rng.uniform(-40, 40, 5000), rng.uniform(-40, 40, 5000)
    z = 2.0 + ((x - 0.5) ** 2 + (y + 1.5) ** 2) / (4 * 30.0)
    fit = fit_paraboloid(np.column_stack([x, y, z]))
    assert (fit.F, fit.x0, fit.y0, fit.z0) == pytest.approx((30.0, 0.5, -1.5, 2.0), rel=1e-10, abs=1e-9)
    with pytest.raises(MeshError, match="not a dish"):
        fit_paraboloid(np.column_stack([x, y, -z]))


def test_unreadable_mesh_is_a_mesh_error(tmp_path: Path):
    bad = tmp_path / "broken.stl"
    bad.write_text("solid nothing\nendsolid\n")
    with pytest.raises(MeshError):
        load_reflector(bad)
    with pytest.raises(MeshError, match="no such mesh file"):
        load_reflector(tmp_path / "missing.ply")


def test_a_binary_stl_cut_short_is_named_so(tmp_path: Path):
    whole = tmp_path / "whole.stl"
    paraboloid(20.0, 8.0, 1.0).mesh.export(whole)
    data = whole.read_bytes()
    n = int.from_bytes(data[80:84], "little")
    assert len(data) == 84 + 50 * n  # the binary STL layout the message reads
    cut = tmp_path / "cut.stl"
    cut.write_bytes(data[: 84 + 50 * (n // 3) + 17])  # a copy stopped a third of the way
    with pytest.raises(MeshError, match=f"cut short: its header counts {n} triangles.*{n // 3} whole"):
        load_reflector(cut)
    noise = tmp_path / "noise.stl"  # bytes that are no STL at all are not called one cut short
    noise.write_bytes(np.random.default_rng(3).bytes(5000))
    with pytest.raises(MeshError, match="holds no triangles"):
        load_reflector(noise)


def test_repeated_and_vertex_repeating_faces_are_dropped_on_loading(tmp_path: Path):
    import trimesh

    source = paraboloid(20.0, 8.0, 0.5)
    clean = tmp_path / "clean.ply"
    source.mesh.export(clean)
    faces = np.asarray(source.faces)
    extra = np.vstack([faces[:50], faces[60:70][:, [1, 2, 0]],  # repeats, one rotated
                       [[0, 0, 1], [1, 1, 1], [2, 3, 2]]])       # no triangles
    trimesh.Trimesh(source.vertices, np.vstack([faces, extra]), process=False).export(tmp_path / "dirty.ply")
    _, want, _ = load_reflector(clean, F=8.0)
    _, got, _ = load_reflector(tmp_path / "dirty.ply", F=8.0)
    assert len(got.faces) == len(faces)
    # the same surface: every face area once (a repeat would count its area, and its currents, twice)
    assert got.mesh.area == pytest.approx(want.mesh.area, rel=1e-12)
    assert np.array_equal(np.sort(np.sort(got.vertices[got.faces], axis=1), axis=0),
                          np.sort(np.sort(want.vertices[want.faces], axis=1), axis=0))


def test_a_mesh_scene_gets_the_sphere_checks_once_its_dish_is_fitted(tmp_path: Path):
    from raysim.maps.sphere import SphereGrid
    from raysim.surface.mesh import reflectors_for

    paraboloid(20.0, 8.0, 0.5).mesh.export(tmp_path / "dish.ply")

    class Scene:  # what reflectors_for reads of a scene
        def __init__(self, sphere):
            self.dish = type("Dish", (), {"mesh": tmp_path / "dish.ply", "mesh_unit": 1.0,
                                          "focal_length": None, "ideal_mesh": None})()
            self.sphere, self.obstacles = sphere, ()
            from raysim.surface.deformation import NoDeformation

            self.deformation = NoDeformation()

    ideal, _ = reflectors_for(Scene(SphereGrid(2.0, 10, 20)))
    assert ideal.F == pytest.approx(8.0, rel=1e-9)
    with pytest.raises(MeshError, match="not above 'sphere.radius_m' = 12 m"):
        reflectors_for(Scene(SphereGrid(12.0, 10, 20)))
    # the rim image of D = 20 m, F = 8 m: 2 atan(20 / 32) = 64.0 deg
    with pytest.raises(MeshError, match="beyond the fitted dish's rim image at 64.01 deg"):
        reflectors_for(Scene(SphereGrid(2.0, 10, 20, np.radians(65.0), np.radians(80.0))))


@pytest.fixture(scope="module")
def mesh_scene_text(tmp_path_factory):
    """A scene naming a D = 10 m, F = 3 m paraboloid mesh, with ``{dish}`` for the extra keys."""
    folder = tmp_path_factory.mktemp("mesh_scene")
    paraboloid(10.0, 3.0, 0.4).mesh.export(folder / "dish.ply")
    text = ('[dish]\nmesh = "dish.ply"\n{dish}\n[source]\nfrequency_hz = 1e10\n'
            "[sphere]\nradius_m = 1.0\nn_theta = 6\nn_phi = 12\n")
    return folder, text


def mesh_reflectors(mesh_scene_text, dish: str):
    from raysim.scene.scene import parse_scene
    from raysim.surface.mesh import reflectors_for

    folder, text = mesh_scene_text
    return reflectors_for(parse_scene(text.format(dish=dish), source="t.toml", base=folder))


@pytest.mark.parametrize(("dish", "F", "D"), [
    ("", 3.0, 10.0),                                    # both fitted / measured
    ("focal_length_m = 3.0\ndiameter_m = 10.0", 3.0, 10.0),
    ("focal_length_m = 3.05", 3.05, 10.0),              # a deliberate override of the fit
    ("diameter_m = 10.05", 3.0, 10.0),                  # D within 1 %: the mesh's D is used
])
def test_a_mesh_scene_that_states_its_dish_consistently_works(mesh_scene_text, dish, F, D):
    ideal, deformed = mesh_reflectors(mesh_scene_text, dish)
    assert ideal.F == pytest.approx(F, rel=1e-6) and deformed.F == ideal.F
    assert ideal.D == pytest.approx(D, rel=1e-6)  # float32 in the file
    # the ideal reflector is the paraboloid of that F through the mesh's own vertices
    x, y, z = ideal.vertices.T
    assert np.allclose(z, (x * x + y * y) / (4 * ideal.F), rtol=0, atol=1e-12)


@pytest.mark.parametrize(("dish", "names"), [
    # 0.26 m RMS from the F = 5 m paraboloid: 21 % of that dish's depth D^2 / 16F = 1.25 m
    ("focal_length_m = 5.0", ("'dish.focal_length_m' = 5 m", "best-fit paraboloid has F = 3 m",
                              "% of the dish's depth, at most 2 %")),
    ("diameter_m = 50.0", ("'dish.diameter_m' = 50 m", "D = 10 m across")),
    ("diameter_m = 10.2", ("'dish.diameter_m' = 10.2 m", "D = 10 m across", "agree to 1 %")),
])
def test_a_mesh_scene_that_contradicts_its_mesh_is_refused(mesh_scene_text, dish, names):
    from raysim.errors import SceneError

    with pytest.raises(SceneError) as info:
        mesh_reflectors(mesh_scene_text, dish)
    text = str(info.value)
    assert "\n" not in text and "dish.ply" in text
    for name in names:
        assert name in text


def _dish_with(tmp_path: Path, extra, name: str) -> Path:
    """A panelled 20 m dish (F = 8 m, nine pieces) written with ``extra`` (a trimesh) added."""
    import trimesh

    dish = paraboloid(20.0, 8.0, 0.5, PanelLayout((0.0, 4.0, 10.0), (1, 8), 0.05)).mesh
    path = tmp_path / name
    trimesh.util.concatenate([dish, extra] if extra is not None else [dish]).export(path)
    return path


def test_pieces_that_are_not_dish_surface_are_refused_by_name(tmp_path: Path):
    """A feed horn at the focus or a loose plate loaded as panels skewed the fit (a 25 m
    dish's F from 7.5 to 8.1 m) and became metres of 'deformation'."""
    import trimesh

    horn = trimesh.creation.cylinder(radius=0.3, height=1.0)
    horn.apply_translation([0.0, 0.0, 8.0])  # at the focus
    plate = trimesh.creation.box((1.0, 1.0, 0.01))
    plate.apply_translation([4.0, 4.0, 3.0])  # 2 m above the surface there
    for extra, where in ((horn, "about (0, 0, 8) m"), (plate, "about (4, 4, 3) m")):
        with pytest.raises(MeshError, match=rf"piece of the mesh is not dish surface: \d+ vertices {re.escape(where)}"):
            load_reflector(_dish_with(tmp_path, extra, "dish.ply"))
    with pytest.raises(MeshError, match="2 pieces of the mesh are not dish surface"):
        load_reflector(_dish_with(tmp_path, trimesh.util.concatenate([horn, plate]), "two.ply"))
    # a one-piece dish with four legs: five pieces, the legs the most of them (the median of
    # the pieces was a leg's, and they passed, F fitted 3.6 m instead of 3)
    one = paraboloid(10.0, 3.0, 0.25).mesh
    legs = []
    for angle in np.radians([45.0, 135.0, 225.0, 315.0]):
        leg = trimesh.creation.box((0.1, 0.1, 3.0))
        leg.apply_translation([4.0 * np.cos(angle), 4.0 * np.sin(angle), 2.5])
        legs.append(leg)
    path = tmp_path / "legs.ply"
    trimesh.util.concatenate([one, *legs]).export(path)
    with pytest.raises(MeshError, match="4 pieces of the mesh are not dish surface"):
        load_reflector(path)


def test_panels_that_all_depart_alike_are_not_stray(tmp_path: Path):
    """A dish whose pieces depart alike from the paraboloid (here a spherical one, 2F in radius,
    panelled) is a dish, if not a paraboloid: it loads, all nine pieces kept."""
    source = paraboloid(20.0, 8.0, 0.5, PanelLayout((0.0, 4.0, 10.0), (1, 8), 0.05))
    mesh = source.mesh.copy()
    r2 = mesh.vertices[:, 0] ** 2 + mesh.vertices[:, 1] ** 2
    mesh.vertices[:, 2] = 16.0 - np.sqrt(16.0**2 - r2)
    path = tmp_path / "sphere.ply"
    mesh.export(path)
    _, loaded, _ = load_reflector(path)
    assert loaded.n_panels == 9


@pytest.mark.parametrize("suffix", [".stl", ".ply"])
def test_panels_that_touch_in_the_ideal_and_part_when_deformed_load_as_a_pair(tmp_path: Path, suffix):
    """Panels without gaps share their edges' positions in the design file but not once each
    is moved: each file merged by its own coincidences gave two triangulations, and the pair
    was refused. The loaded deformation is each panel's piston (less the fit's)."""
    import trimesh

    layout = PanelLayout((0.0, 1.7, 3.4, 5.0), (6, 12, 18), 0.0)
    design = paraboloid(10.0, 3.0, 0.25, layout)
    piston = np.random.default_rng(0).normal(0.0, 100e-6, layout.n_panels)
    moved = design.vertices.copy()
    moved[:, 2] += piston[design.vertex_panel]
    trimesh.Trimesh(design.vertices, design.faces, process=False).export(tmp_path / f"ideal{suffix}")
    trimesh.Trimesh(moved, design.faces, process=False).export(tmp_path / f"dish{suffix}")
    ideal, loaded, _ = load_reflector(tmp_path / f"dish{suffix}", F=3.0, ideal_path=tmp_path / f"ideal{suffix}")
    assert loaded.n_panels == layout.n_panels
    assert np.array_equal(ideal.faces, loaded.faces) and len(loaded.faces) == len(design.faces)
    # face k is the files' face k (rewound at most): its corners moved by its panel's piston,
    # the fit's shift being the same for both (float32 in STL: 1e-6 m of 5 m)
    dz = loaded.vertices[:, 2] - ideal.vertices[:, 2]
    expected = piston[design.vertex_panel[design.faces[:, 0]]]
    assert np.allclose(dz[loaded.faces], expected[:, None], atol=2e-6)


def _sheet():
    """A one-piece 10 m dish (F = 3 m) as a trimesh."""
    return paraboloid(10.0, 3.0, 0.5).mesh


def test_a_dish_exported_as_a_solid_is_refused(tmp_path: Path):
    """A panel exported as a solid (front, back 2 cm lower, side walls) loaded as a dish: the
    ideal (the mesh moved onto the paraboloid) put the back on the front and reflected the
    aperture twice, FA 17.6 RMS with no deformation, exit 0. Two layers and side walls are each
    refused, naming what was found; the front sheet alone loads."""
    import trimesh

    front = _sheet()
    back = trimesh.Trimesh(front.vertices - [0.0, 0.0, 0.02], front.faces[:, ::-1], process=False)
    trimesh.util.concatenate([front, back]).export(tmp_path / "layers.ply")
    with pytest.raises(MeshError, match=r"covers its footprint 2.00 times: it holds more than one layer"):
        load_reflector(tmp_path / "layers.ply")
    # the rim's edges (each used by one face) drawn 5 cm down as a wall, joined to the sheet
    edges = np.sort(front.edges, axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    rim = unique[count == 1]
    n = len(front.vertices)
    low = front.vertices[rim.ravel()] - [0.0, 0.0, 0.05]
    k = n + 2 * np.arange(len(rim))
    walls = np.concatenate([np.column_stack([rim[:, 0], rim[:, 1], k + 1]),
                            np.column_stack([rim[:, 0], k + 1, k])])
    trimesh.Trimesh(np.vstack([front.vertices, low]), np.vstack([front.faces, walls]),
                    process=False).export(tmp_path / "walls.ply")
    with pytest.raises(MeshError, match=r"% of its area is side walls"):
        load_reflector(tmp_path / "walls.ply")
    front.export(tmp_path / "front.ply")
    assert load_reflector(tmp_path / "front.ply")[1].n_panels == 1


def test_a_patch_exported_twice_is_refused_and_a_panelled_dish_is_not(tmp_path: Path):
    """QA: a 12 m dish with a copy of a 1.6 m patch 2 mm above it (panels overlapping at a
    seam) loaded: it covers its footprint 1.02 times, under the two-layer test's bound, and the
    shadow test's tolerance (1 mm plus the facets' sag) let both layers reflect, 1.8 % more
    power on the sphere than falls on the aperture with the power balance at round-off. The
    faces over the patch's area are now found under two faces (its area, from shapely's union
    of the patch's triangles, independently), and refused; a dish of panels with gaps, whose
    pieces never overlap, still loads."""
    import trimesh

    front = _sheet()
    centres = front.triangles_center
    near = np.hypot(centres[:, 0] - 2.0, centres[:, 1]) < 0.6
    patch = trimesh.Trimesh(front.vertices + np.array([0.0, 0.0, 0.002]), front.faces[near], process=False)
    patch.remove_unreferenced_vertices()
    trimesh.util.concatenate([front, patch]).export(tmp_path / "seam.ply")
    area = shapely.unary_union([shapely.Polygon(t[:, :2]) for t in patch.triangles]).area
    with pytest.raises(MeshError, match=r"lie under two faces or more") as info:
        load_reflector(tmp_path / "seam.ply")
    stated = float(re.search(r"([0-9.]+) m\^2", str(info.value)).group(1))
    assert abs(stated - area) < 0.05 * area, (stated, area)
    panelled = paraboloid(10.0, 3.0, 0.3, PanelLayout((0.0, 2.5, 5.0), (6, 12), 0.02)).mesh
    panelled.export(tmp_path / "panels.ply")
    assert load_reflector(tmp_path / "panels.ply")[1].n_panels == 18


def test_a_textured_or_rewritten_mesh_is_one_piece(tmp_path: Path):
    """A mesh whose every face has corners of its own (a textured OBJ: the corners differ by
    their texture coordinates; a CAD export: by rounding, 1e-7 m) loaded with each triangle a
    panel: go+edge diffracted from 68 688 edge points instead of 378, and FA moved by 9 times
    its RMS. Both now load as the one piece they are, and as the shared-vertex file does."""
    import trimesh
    from trimesh.visual import TextureVisuals

    sheet = _sheet()
    corners = sheet.vertices[sheet.faces].reshape(-1, 3)
    soup_faces = np.arange(len(corners)).reshape(-1, 3)
    rng = np.random.default_rng(1)
    uv = rng.random((len(corners), 2))
    trimesh.Trimesh(corners, soup_faces, visual=TextureVisuals(uv=uv),
                    process=False).export(tmp_path / "textured.obj")
    trimesh.Trimesh(corners + rng.normal(0.0, 1e-7, corners.shape), soup_faces,
                    process=False).export(tmp_path / "rewritten.ply")
    sheet.export(tmp_path / "shared.ply")
    reference = load_reflector(tmp_path / "shared.ply")[1]
    for name in ("textured.obj", "rewritten.ply"):
        loaded = load_reflector(tmp_path / name)[1]
        assert loaded.n_panels == 1, name
        assert len(loaded.vertices) == len(reference.vertices) and len(loaded.faces) == len(reference.faces)


def test_faces_of_no_area_are_dropped(tmp_path: Path):
    """Faces (a, midpoint of ab, b) gave NaN normals and edges: the deformed map wholly NaN
    (po+ptd, go+edge), exit 0, and the midpoints counted as 0.2 mm of departure. They are
    dropped: the mesh loads as it would without them."""
    import trimesh

    sheet = _sheet()
    ab = sheet.faces[:40, :2]
    mid = 0.5 * (sheet.vertices[ab[:, 0]] + sheet.vertices[ab[:, 1]])
    flat = np.column_stack([ab[:, 0], len(sheet.vertices) + np.arange(40), ab[:, 1]])
    trimesh.Trimesh(np.vstack([sheet.vertices, mid]), np.vstack([sheet.faces, flat]),
                    process=False).export(tmp_path / "flat.ply")
    sheet.export(tmp_path / "clean.ply")
    (ideal, loaded, _), (clean_ideal, clean, _) = (load_reflector(tmp_path / n)
                                                   for n in ("flat.ply", "clean.ply"))
    assert len(loaded.faces) == len(clean.faces) and len(loaded.vertices) == len(clean.vertices)
    assert np.all(np.isfinite(loaded.vertex_normals))
    assert mesh_departure_rms(ideal, loaded) == pytest.approx(mesh_departure_rms(clean_ideal, clean),
                                                              rel=1e-6)
