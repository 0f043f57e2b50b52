"""PO of the paper's dish: GO limit with a tapered current, refinement stability, the FieldMap."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from raysim.errors import DeviceError, RaysimError
from raysim.maps.fieldmap import validate
from raysim.maps.sphere import ideal_go_intensity
from raysim.optics import po
from raysim.scene.scene import load_scene
from raysim.simulate import simulate
from raysim.surface.mesh import paraboloid, reflectors_for
from tests.surfaces import smooth_taper

D, F, R = 110.0, 33.0, 10.0
SCENES = Path(__file__).resolve().parents[3] / "scenes"


def sphere_points(theta_deg, phi_deg):
    """Points on the probe sphere (R about the focus) at the given angles, and their theta."""
    T, P = np.meshgrid(np.radians(theta_deg), np.radians(phi_deg), indexing="ij")
    d = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), -np.cos(T)], axis=-1)
    return (np.array([0.0, 0.0, F]) + R * d).reshape(-1, 3), T.ravel()


@pytest.mark.slow
def test_tapered_paraboloid_at_3ghz_is_go():
    """With the rim's edge wave removed, PO on the paper's dish is GO's (rho/R)^2 (theta <= 40 deg).

    The taper (1 inside r = 35 m, smoothly 0 at the 55 m rim) acts only on rays that reach the
    sphere beyond theta = 56 deg.
    """
    wave = po.Illumination.plane_wave(3e9, (0, 0, -1), (1, 0, 0))
    points, theta = sphere_points(np.arange(0.5, 40.0, 6.5), [0.5, 45.5, 90.5])
    assert np.degrees(theta.max()) == pytest.approx(39.5)
    result = po.scatter(paraboloid(D, F, 5.0), points, wave, samples_per_wavelength=1.0,
                        taper=smooth_taper(35.0, D / 2))
    intensity = np.sum(np.abs(result.E) ** 2, axis=1)
    rel = intensity / ideal_go_intensity(theta, F, R) - 1.0
    assert np.abs(rel).max() < 1e-3, np.abs(rel).max()


@pytest.fixture(scope="module")
def paper_pair():
    return reflectors_for(load_scene(SCENES / "paper_po.toml"))


@pytest.mark.slow
def test_paper_case_is_stable_under_refinement(paper_pair):
    """Default sampling against a finer one: FA and the intensities move by < 1e-4 of the signal."""
    ideal, deformed = paper_pair
    wave = po.Illumination.plane_wave(0.3e9, (0, 0, -1), (1, 0, 0))
    points, _ = sphere_points([0.5, 10.5, 30.5, 50.5, 70.5, 78.5, 79.5, 80.5, 85.5, 89.5],
                              [0.5, 45.5, 90.5])

    def run(spw):
        i = np.sum(np.abs(po.scatter(ideal, points, wave, spw).E) ** 2, axis=1)
        d = np.sum(np.abs(po.scatter(deformed, points, wave, spw).E) ** 2, axis=1)
        return i, d, i / d - 1.0

    I0, I1, FA = run(po.DEFAULT_SAMPLES_PER_WAVELENGTH)
    J0, J1, FA_fine = run(2.5)
    signal = np.sqrt(np.mean(FA_fine**2))
    assert 1e-3 < signal < 3e-2  # the paper's deformation gives FA of some 1e-3
    worst = max(np.abs(FA - FA_fine).max(), np.abs(I0 / J0 - 1).max(), np.abs(I1 / J1 - 1).max())
    assert worst < 1e-4 * signal, worst / signal
    # a coarser sampling is measurably off: the check can fail
    C0, _, _ = run(0.75)
    assert np.abs(C0 / J0 - 1).max() > 10 * worst


@pytest.fixture(scope="module")
def small_scene():
    scene = load_scene(SCENES / "paper_po.toml").with_overrides(0.15e9, 6, 8)
    return replace(scene, sphere=replace(scene.sphere, theta_max=np.radians(60.0)))


def test_simulate_po_fieldmap(small_scene):
    ds = simulate(small_scene, method="po", save_field=True)
    validate(ds)
    assert ds.attrs["method"] == "po" and ds.attrs["sampling"] == "centre"
    assert ds.attrs["field"] == "scattered"
    assert ds.attrs["samples_per_wavelength"] == po.DEFAULT_SAMPLES_PER_WAVELENGTH
    assert ds.attrs["samples_lit"] == ds.attrs["samples"] > 0
    E = ds["E_re"].values + 1j * ds["E_im"].values
    np.testing.assert_allclose(ds["intensity"].values, np.sum(np.abs(E) ** 2, axis=-1), rtol=1e-14)
    assert list(ds["component"].values) == ["x", "y", "z"]
    # the deformation changes the map, by a small ratio
    FA = ds["intensity_ideal"].values / ds["intensity"].values - 1.0
    assert 0 < np.abs(FA).max() < 0.2

    # --total adds E_inc = x_hat exp(+j k z) at every probe point, nothing else
    total = simulate(small_scene, method="po", total=True, save_field=True)
    assert total.attrs["field"] == "total"
    k = 2 * np.pi * small_scene.source.frequency_hz / po.C0
    z = small_scene.sphere.points(F)[..., 2]
    E_inc = np.zeros_like(E)
    E_inc[..., 0] = np.exp(1j * k * z)
    np.testing.assert_allclose(total["E_re"].values + 1j * total["E_im"].values, E + E_inc,
                               rtol=0, atol=1e-12)


def test_po_only_options_and_bad_values(small_scene):
    # go+edge takes --total too, so the message names every wave method (it named po only)
    with pytest.raises(RaysimError, match=r"apply to the wave methods \(po, po\+ptd, go\+edge\), "
                                          r"not go$"):
        simulate(small_scene, method="go", total=True)
    with pytest.raises(RaysimError, match=r"must lie in \(0, 20\]"):
        simulate(small_scene, method="po", samples_per_wavelength=0.0)


def test_cli_simulate_po(tmp_path, small_scene, raysim_cli):
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(small_scene.text.replace("theta_max_deg = 90.0", "theta_max_deg = 60.0"))
    out = tmp_path / "po.nc"
    result = raysim_cli("simulate", scene_file, "-o", out, "--method", "po", "--frequency", "1.5e8",
                        "--n-theta", "6", "--n-phi", "8", "--samples-per-wavelength", "2", "--total")
    assert result.code == 0, result.stderr
    with xr.open_dataset(out) as ds:
        assert ds.attrs["method"] == "po" and ds.attrs["field"] == "total"
        assert ds.attrs["samples_per_wavelength"] == 2.0
        assert ds.sizes == {"theta": 6, "phi": 8}


def test_cuda_without_a_gpu_is_one_clear_error():
    from raysim.optics.runtime import init

    if init().is_cuda_available():
        pytest.skip("a GPU is present: the CUDA path runs instead")
    wave = po.Illumination.plane_wave(0.3e9, (0, 0, -1), (1, 0, 0))
    with pytest.raises(DeviceError, match="no CUDA GPU"):
        po.scatter(paraboloid(D, F, 5.0), np.array([[0.0, 0.0, 25.0]]), wave, device="cuda")


def test_a_sphere_close_above_the_vertex_is_warned_of_with_the_default_quadrature():
    """With the sphere a few wavelengths above the vertex, PO's default 1.5 samples per
    wavelength left FA tens of per cent off, and nothing said so. The FieldMap now records how
    far above the vertex the sphere passes, and warns while that is under six wavelengths and
    the quadrature is the default."""
    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate, summary

    text = ('name = "near"\n[dish]\ndiameter_m = 5.0\nfocal_length_m = 2.0\nresolution_m = 0.25\n'
            "[source]\nfrequency_hz = 1e9\n[sphere]\nradius_m = {R}\nn_theta = 4\nn_phi = 8\n")
    wavelength = 299792458.0 / 1e9
    near = simulate(parse_scene(text.format(R=1.5)), method="po")
    assert near.attrs["sphere_gap_wavelengths"] == pytest.approx(0.5 / wavelength, rel=1e-6)
    assert "WARNING: the sphere passes 1.7 wavelengths above" in summary(near)
    given = simulate(parse_scene(text.format(R=1.5)), method="po", samples_per_wavelength=3.0)
    assert "quadrature_warning" not in given.attrs
    far = simulate(parse_scene(text.format(R=0.1)), method="po")  # 6.3 wavelengths above
    assert "quadrature_warning" not in far.attrs and "WARNING" not in summary(far)
