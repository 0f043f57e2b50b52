"""``raysim campaign`` end to end on a coarse scan: files, the unknown gain recovered, the
summary's prediction and figure reached (the full-size campaign's figures are in README)."""

from pathlib import Path

import numpy as np
import pytest

from raysim.maps import surfacemap
from raysim.pipeline.campaign import run_campaign
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
