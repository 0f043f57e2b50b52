"""``raysim campaign`` end to end on a coarse scan: files, the unknown gain recovered, the
summary's prediction and figure reached (the full-size campaign's figures are in README)."""

from pathlib import Path

import numpy as np
import pytest

from raysim.maps import fieldmap, surfacemap
from raysim.pipeline.campaign import run_campaign
from solver.errors import SolverError
from tests.cli import run_cli
from tests.hardware.conftest import write_plan

SCENE = """
name = "coarse_campaign"
[dish]
diameter_m = 110.0
focal_length_m = 33.0
resolution_m = 1.0
[[deformation]]
type = "zernike"
terms = [[2, 2, 100.0]]
[source]
frequency_hz = 0.3e9
[sphere]
radius_m = 10.0
n_theta = 45
n_phi = 90
"""


@pytest.fixture()
def inputs(tmp_path: Path) -> tuple[Path, Path]:
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE)
    plan = write_plan(tmp_path, theta_max=80.0, theta_step=5.0, phi_step=10.0, samples=1,
                      noise=0.01, every=4)
    plan.write_text(plan.read_text().replace("[simulator]", "[simulator]\ngain_db = 0.3"))
    return scene, plan


def test_a_campaign_estimates_the_unknown_gain_and_reports_its_figures(inputs, tmp_path):
    scene, plan = inputs
    result = run_campaign(scene, plan, tmp_path / "c", rim=32, N=64, refine=1)
    names = sorted(p.name for p in result.folder.iterdir())
    assert names == ["campaign.txt", "field.nc", "rim.csv", "scan.nc", "scan.nc.journal",
                     "surface.nc"]
    assert result.gain_injected == pytest.approx(10 ** 0.03)
    assert result.gain_estimated == pytest.approx(result.gain_injected, rel=2e-3)
    surface = surfacemap.load(result.folder / "surface.nc")
    assert not surface.attrs["gain_known"] and surface.attrs["harmonic_part"] == "fixed by rim targets"
    assert np.isfinite(result.achieved) and result.achieved > 0 and result.predicted > 0
    text = (result.folder / "campaign.txt").read_text()
    assert f"{result.predicted * 1e6:.1f} um" in text and f"{result.achieved * 1e6:.1f} um" in text


def test_the_command_prints_the_summary(inputs, tmp_path):
    scene, plan = inputs
    out = run_cli("campaign", str(scene), str(plan), "-o", str(tmp_path / "c"), "--rim", "32",
                  "--grid", "64", "--refine", "0", cwd=tmp_path)
    assert out.code == 0, out.stderr
    assert "predicted RMS (raysim budget)" in out.stdout and "achieved RMS" in out.stdout


OBSTACLES = """
[[obstacle]]
type = "disk"
radius_m = 2.5
[[obstacle]]
type = "legs"
count = 4
width_m = 0.8
foot_radius_m = 40.0
apex_radius_m = 2.5
rotation_deg = 45.0
"""


def test_a_campaign_with_a_cabin_and_a_quadripod_masks_their_cells(inputs, tmp_path):
    scene, plan = inputs
    scene.write_text(scene.read_text() + OBSTACLES)
    # the drift reference off the pole, which the cabin hides
    plan.write_text(plan.read_text().replace("[acquisition]", "[acquisition]\nreference_theta_deg = 30.0")
                    + OBSTACLES)
    result = run_campaign(scene, plan, tmp_path / "c", rim=32, N=64, refine=1)
    measured = fieldmap.load(result.folder / "scan.nc")
    blocked = measured["blocked"].values.astype(bool)
    assert blocked[0].all() and 0.05 < blocked.mean() < 0.4   # the cabin's rows, the legs
    surface = surfacemap.load(result.folder / "surface.nc")
    assert surface.attrs["samples_blocked"] > 0 and surface.attrs["central_hole_radius_m"] > 2.5
    assert result.gain_estimated == pytest.approx(result.gain_injected, rel=2e-3)
    assert np.isfinite(result.achieved) and result.predicted > 0
    # a plan without the scene's obstacles is refused before any work
    plan.write_text(plan.read_text().replace(OBSTACLES, ""))
    with pytest.raises(SolverError, match="the plan's obstacles none are not the scene's"):
        run_campaign(scene, plan, tmp_path / "d", rim=32, N=64, refine=1)


def test_a_campaign_refuses_an_output_folder_holding_a_file_the_scene_names(inputs, tmp_path):
    """The scene's deformation map lies in the output folder (the surface an earlier campaign
    measured): replacing the folder would destroy it, so the command stops first."""
    import xarray as xr

    scene, plan = inputs
    prev = tmp_path / "prev"
    prev.mkdir()
    x = np.linspace(-56.0, 56.0, 57)
    X, Y = np.meshgrid(x, x)
    xr.Dataset({"deformation": (("y", "x"), 200e-6 * np.exp(-((X - 20) ** 2 + Y**2) / 50), {"units": "m"})},
               coords={"x": x, "y": x}).to_netcdf(prev / "surface.nc")
    before = (prev / "surface.nc").read_bytes()
    text = scene.read_text().replace('type = "zernike"\nterms = [[2, 2, 100.0]]',
                                     'type = "map"\nfile = "prev/surface.nc"')
    scene.write_text(text)
    out = run_cli("campaign", str(scene), str(plan), "-o", str(prev), "--rim", "0", "--grid", "32",
                  "--refine", "0", cwd=tmp_path)
    assert out.code == 2
    line = out.error()
    assert "surface.nc" in line and "destroy the input" in line
    assert (prev / "surface.nc").read_bytes() == before
    assert sorted(p.name for p in prev.iterdir()) == ["surface.nc"]


def test_a_campaign_whose_scene_does_not_hold_the_plan_is_refused_before_simulating(inputs, tmp_path):
    """A scene simulated to theta 40 deg under a plan to 80 deg ran to the end with the map's
    edge row read for every cell beyond it (exit 0); a plan at another frequency than the
    scene's was scanned as the scene's. Both are refused in one line, nothing written."""
    from hardware.errors import PlanError

    _, plan = inputs
    short = tmp_path / "short.toml"
    short.write_text(SCENE.replace("n_theta = 45", "n_theta = 20\ntheta_max_deg = 40.0"))
    with pytest.raises(PlanError, match="covers theta 0..40 deg.*the first at theta 42.5 deg"):
        run_campaign(short, plan, tmp_path / "a")
    other = tmp_path / "other.toml"
    other.write_text(SCENE.replace("frequency_hz = 0.3e9", "frequency_hz = 1.2e9"))
    with pytest.raises(PlanError, match="is at 1.2 GHz, the plan reads at 0.3 GHz"):
        run_campaign(other, plan, tmp_path / "b")
    # QA: a scene on another sphere than the rig's track was scanned and labelled the track's R
    wide = tmp_path / "wide.toml"
    wide.write_text(SCENE.replace("radius_m = 10.0", "radius_m = 12.0"))
    with pytest.raises(PlanError, match="radius 12 m, the rig's track has R = 10 m"):
        run_campaign(wide, plan, tmp_path / "c")
    assert not any((tmp_path / d).exists() for d in "abc")


def test_a_file_written_into_the_output_folder_during_the_campaign_is_kept(inputs, tmp_path):
    """QA: notes.txt written into the empty output folder 10 s into the run was deleted when
    the result replaced the folder, exit 0. Now the command ends with one line naming where
    the result is, status 2, and the notes and the result are both there."""
    from raysim.render.backend import RenderError

    scene, plan = inputs
    out = tmp_path / "c"
    out.mkdir()

    def crew(stage: str, fraction: float) -> None:
        if stage == "invert":
            (out / "notes.txt").write_text("crew notes")

    with pytest.raises(RenderError, match="notes.txt appeared in it during the run"):
        run_campaign(scene, plan, out, rim=32, N=64, refine=1, progress=crew)
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    assert (out / "notes.txt").read_text() == "crew notes"
    kept = tmp_path / "c.new"
    assert "campaign.txt" in {p.name for p in kept.iterdir()}
    surfacemap.load(kept / "surface.nc")  # the result is whole
