"""Scenes: the paper's case as the paper states it, and one clear error per bad input."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from raysim.errors import RaysimError, SceneError
from raysim.scene.scene import load_scene, parse_scene
from raysim.surface.deformation import GaussianBumps, PanelRigid, PaperDeformation, Sum, Zernike
from raysim.surface.gridded import GriddedMap
from tests.surfaces import disk_rms

BASE = """
[dish]
diameter_m = 110.0
focal_length_m = 33.0

[source]
frequency_hz = 3.0e8

[sphere]
radius_m = 10.0
"""


def scene_with(extra: str = "", base: str = BASE, **replace: str):
    text = base
    for old, new in replace.items():
        text = text.replace(old, new)
    return parse_scene(text + extra, source="test.toml")


def test_paper_scene_is_the_papers_table_2(paper_scene):
    s = paper_scene
    assert (s.D, s.F, s.sphere.radius) == (110.0, 33.0, 10.0)
    assert s.source.frequency_hz == 0.3e9
    assert (s.sphere.n_theta, s.sphere.n_phi) == (90, 360)
    # cell centres 0.5 .. 89.5 deg in 1 deg steps (docs/physics.md)
    assert np.allclose(np.degrees(s.sphere.theta[[0, -1]]), [0.5, 89.5])
    assert np.allclose(np.degrees(s.sphere.phi[[0, -1]]), [0.5, 359.5])
    assert isinstance(s.deformation, PaperDeformation) and s.deformation.scale == 1.0
    # the source travels along -z with E along x (docs/physics.md's PO convention)
    assert np.allclose(s.source.direction, [0, 0, -1])
    assert np.allclose(s.source.e_hat, [1, 0, 0])
    assert "Eq. 8" in s.text or "deformation" in s.text


def test_panels_scene_has_eight_rings_of_gapped_panels(panels_scene):
    layout = panels_scene.panels
    assert layout.n_rings == 8 and layout.gap == 0.010
    assert isinstance(panels_scene.deformation, PanelRigid)
    # the scene's 50 um RMS over the panels, by an independent quadrature of the surface
    rms = disk_rms(panels_scene.deformation, 0.5 * panels_scene.D, layout, panels_only=True)
    assert rms == pytest.approx(50e-6, rel=2e-3)


def test_source_direction_and_polarisation_off_axis():
    text = BASE.replace("frequency_hz = 3.0e8", "frequency_hz = 3.0e8\nincidence_theta_deg = 30.0\n"
                        "incidence_phi_deg = 90.0\npolarization_deg = 90.0")
    src = parse_scene(text).source
    # arrives from 30 deg off axis in the y-z plane, travelling down and towards -y
    assert np.allclose(src.direction, [0.0, -0.5, -math.sqrt(3) / 2])
    assert abs(np.dot(src.e_hat, src.direction)) < 1e-15
    assert np.linalg.norm(src.e_hat) == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"diameter_m = 110.0": "diameter = 110.0"}, "unknown key 'dish.diameter' (did you mean 'diameter_m'?)"),
        ({"radius_m = 10.0": "radius_m = 40.0"}, "'sphere.radius_m' = 40 m must be smaller than the focal length"),
        ({"diameter_m = 110.0": "diameter_m = -5.0"}, "'dish.diameter_m' must be > 0"),
        ({"diameter_m = 110.0": "diameter_m = 110000.0"}, "is it in mm?"),
        ({"frequency_hz = 3.0e8": "frequency_hz = 0.3"}, "for 0.3 GHz write 3e+08"),
        ({"frequency_hz = 3.0e8": 'frequency_hz = "300 MHz"'}, "must be a number"),
        ({"radius_m = 10.0": "radius_m = 10.0\ntheta_max_deg = 95.0"}, "'sphere.theta_max_deg' must be <= 90"),
        ({"radius_m = 10.0": "radius_m = 10.0\ntheta_min_deg = 85.0"}, "beyond the rim image at 79.61 deg"),
        ({"radius_m = 10.0": "radius_m = 10.0\nn_theta = 0"}, "'sphere.n_theta' must be an integer in 1..9000"),
        ({"[sphere]": "[spheres]"}, "unknown key 'spheres'"),
        ({"[dish]": 'method = "fdtd"\n[dish]'}, "'method' must be one of go, po, po+ptd, go+edge, got 'fdtd'"),
    ],
)
def test_bad_values_name_the_key(change, message):
    with pytest.raises(SceneError) as info:
        scene_with(**change)
    text = str(info.value)
    assert message in text
    assert "\n" not in text and text.startswith("test.toml: ")


def test_scene_method_is_simulates_default():
    from raysim.simulate import simulate

    assert parse_scene(BASE).method == "go"
    scene = parse_scene('method = "po"\n' + BASE)
    assert scene.method == "po"
    # the scene's method runs unless the call names another; po's checks then apply
    with pytest.raises(RaysimError, match=r"must lie in \(0, 20\]"):
        simulate(scene, samples_per_wavelength=0.0)
    with pytest.raises(RaysimError, match="applies to --method po"):
        simulate(scene, method="go", samples_per_wavelength=2.0)


def test_missing_required_key_is_named():
    with pytest.raises(SceneError, match="missing key 'sphere.radius_m'"):
        scene_with(**{"radius_m = 10.0": "n_theta = 9"})


def test_toml_syntax_error_is_one_line():
    with pytest.raises(SceneError, match="not valid TOML"):
        parse_scene("[dish\n", source="x.toml")


def test_panel_gap_in_wrong_units_is_refused():
    panels = "\n[panels]\nring_edges_m = [0.0, 20.0, 55.0]\npanels_per_ring = [6, 12]\ngap_m = 10.0\n"
    with pytest.raises(SceneError, match="'panels.gap_m' = 10 m .* is it in mm"):
        scene_with(panels)


def test_rings_must_end_at_the_rim():
    panels = "\n[panels]\nring_edges_m = [0.0, 20.0, 50.0]\npanels_per_ring = [6, 12]\n"
    with pytest.raises(SceneError, match="must end at the rim D/2 = 55"):
        scene_with(panels)


def test_deformation_kinds_and_their_sum(tmp_path: Path):
    csv = tmp_path / "map.csv"
    xs = np.linspace(-60, 60, 13)
    rows = ["x,y,dz"] + [f"{x},{y},{1e-5 * x}" for y in xs for x in xs]
    csv.write_text("\n".join(rows))
    table = tmp_path / "panels.csv"
    table.write_text("panel,piston_um,tilt_x_urad,tilt_y_urad\n0,10,1,-1\n7,-5,0,2\n")
    extra = f"""
[panels]
ring_edges_m = [0.0, 20.0, 55.0]
panels_per_ring = [6, 12]
gap_m = 0.01

[[deformation]]
type = "paper"
peak_to_peak_um = 400.0

[[deformation]]
type = "zernike"
terms = [[2, 2, 200.0], [3, 1, -50.0]]

[[deformation]]
type = "bumps"
bumps = [{{x_m = 10.0, y_m = -5.0, amplitude_um = 30.0, sigma_m = 2.0}}]

[[deformation]]
type = "panel_rigid"
table = "{table.name}"

[[deformation]]
type = "map"
file = "{csv.name}"
"""
    s = parse_scene(BASE + extra, source=str(tmp_path / "s.toml"), base=tmp_path)
    assert isinstance(s.deformation, Sum)
    kinds = [type(p) for p in s.deformation.parts]
    assert kinds == [PaperDeformation, Zernike, GaussianBumps, PanelRigid, GriddedMap]
    paper = s.deformation.parts[0]
    r = np.linspace(0, 55, 100001)
    assert np.ptp(paper.radial_profile(r)) == pytest.approx(400e-6, rel=1e-6)
    rigid = s.deformation.parts[3]
    assert rigid.piston[0] == pytest.approx(10e-6) and rigid.tilt_y[7] == pytest.approx(2e-6)
    # the sum is the sum of its parts at any point
    x, y = np.array([3.0, -20.0, 40.0]), np.array([1.0, 7.0, -30.0])
    total = sum(p(x, y) for p in s.deformation.parts)
    assert np.allclose(s.deformation(x, y), total, rtol=0, atol=1e-18)


def test_panel_rigid_needs_panels():
    with pytest.raises(SceneError, match="needs a \\[panels\\] layout"):
        scene_with('\n[[deformation]]\ntype = "panel_rigid"\nrms_um = 50.0\n')


def test_bad_zernike_index_is_refused():
    with pytest.raises(SceneError, match=r"Zernike \(n=2, m=1\) does not exist"):
        scene_with('\n[[deformation]]\ntype = "zernike"\nterms = [[2, 1, 5.0]]\n')


def test_overrides_check_their_values(paper_scene):
    s = paper_scene.with_overrides(frequency_hz=1e9, n_theta=45, n_phi=180)
    assert s.source.frequency_hz == 1e9 and s.sphere.n_theta == 45 and s.sphere.dtheta == pytest.approx(
        math.radians(2.0))
    with pytest.raises(SceneError, match="--n-phi must be an integer in 1..36000"):
        paper_scene.with_overrides(n_phi=0)


def test_high_order_zernike_scene_keeps_its_size_and_the_order_is_bounded():
    # QA: 1 um of Z(60, 0) made a 3 m surface; Noll-normalised it peaks at sqrt(61) um on the rim
    s = scene_with('\n[[deformation]]\ntype = "zernike"\nterms = [[60, 0, 1.0]]\n')
    r = np.linspace(0.0, 55.0, 20001)
    values = s.deformation(r, np.zeros_like(r))
    assert np.abs(values).max() == pytest.approx(math.sqrt(61) * 1e-6, rel=1e-12)
    with pytest.raises(SceneError, match=r"Zernike \(n=200, m=0\): radial order n is over 100") as info:
        scene_with('\n[[deformation]]\ntype = "zernike"\nterms = [[200, 0, 1.0]]\n')
    assert "\n" not in str(info.value) and str(info.value).startswith("test.toml: ")


def test_overrides_take_numpy_integers_but_not_bools_or_floats(paper_scene):
    s = paper_scene.with_overrides(n_theta=np.int64(18), n_phi=np.int32(72))
    assert (s.sphere.n_theta, s.sphere.n_phi) == (18, 72)
    assert type(s.sphere.n_theta) is int and type(s.sphere.n_phi) is int
    assert s.sphere.dtheta == pytest.approx(math.radians(5.0))
    for bad in (True, np.bool_(True), 18.0, np.float64(18.0), "18"):
        with pytest.raises(SceneError, match="--n-theta must be an integer in 1..9000"):
            paper_scene.with_overrides(n_theta=bad)
    with pytest.raises(SceneError, match="--n-theta must be an integer in 1..9000"):
        paper_scene.with_overrides(n_theta=np.int64(9001))
    # cells counted in Python integers: 9000 x 30000 in int16 would wrap round below the limit
    with pytest.raises(SceneError, match="270,000,000 cells is over the limit"):
        paper_scene.with_overrides(n_theta=np.int16(9000), n_phi=np.int16(30000))


def test_scene_files_in_repo_load(repo_root: Path):
    for path in sorted((repo_root / "scenes").glob("*.toml")):
        text = path.read_text()
        if "[dish]" in text:  # scan plans and dataset specs have their own loaders
            assert load_scene(path).name
