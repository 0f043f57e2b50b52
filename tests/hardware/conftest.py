"""Shared helpers for the hardware tests: small plans, rig files, synthetic FieldMaps; the CLI
runners are the suite's (tests/cli.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from raysim.maps.fieldmap import fieldmap, save
from raysim.maps.sphere import SphereGrid, ideal_go_intensity
from tests.cli import cli_env, error_line, run_cli  # noqa: F401  (the tests import them from here)

ROOT = Path(__file__).resolve().parents[2]
F, D, R = 33.0, 110.0, 10.0

RIG_TOML = """
[track]
radius_m = {radius}
centre_offset_m = [0.0, 0.0, 0.0]

[limits]
slider_min_deg = -95.0
slider_max_deg = 95.0
rotation_min_deg = -5.0
rotation_max_deg = 185.0

[park]
slider_deg = 95.0
rotation_deg = 0.0

[motion]
speed_deg_s = 10.0
tolerance_deg = 0.001
timeout_s = {move_timeout}

[instruments]
timeout_s = {visa_timeout}
"""

PLAN_TOML = """
rig = "rig.toml"

[reflector]
focal_length_m = {F}
diameter_m = {D}
frequency_hz = 3.0e8

[grid]
theta_min_deg = 0.0
theta_max_deg = {theta_max}
theta_step_deg = {theta_step}
phi_min_deg = 0.0
phi_max_deg = 360.0
phi_step_deg = {phi_step}

[acquisition]
samples_per_point = {samples}
reference_samples = {reference_samples}
reference_every_lines = {every}
drift_correction = "{drift_correction}"
power_unit_dbm = -20.0

[simulator]
seed = {seed}
noise_db = {noise}
drift_db = {drift}
drift_period_samples = 60
time_scale = {time_scale}
"""


def write_plan(folder: Path, *, theta_max: float = 60.0, theta_step: float = 20.0,
               phi_step: float = 60.0, samples: int = 2, every: int = 2, seed: int = 3,
               noise: float = 0.0, drift: float = 0.0, time_scale: float = 0.0,
               visa_timeout: float = 0.5, move_timeout: float = 5.0, radius: float = R,
               reference_samples: int = 2, drift_correction: str = "smooth") -> Path:
    """A plan and its rig.toml in ``folder``; returns the plan's path."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "rig.toml").write_text(RIG_TOML.format(radius=radius, visa_timeout=visa_timeout,
                                                     move_timeout=move_timeout))
    plan = folder / "plan.toml"
    plan.write_text(PLAN_TOML.format(F=F, D=D, theta_max=theta_max, theta_step=theta_step,
                                     phi_step=phi_step, samples=samples, every=every, seed=seed,
                                     noise=noise, drift=drift, time_scale=time_scale,
                                     reference_samples=reference_samples,
                                     drift_correction=drift_correction))
    return plan


def pattern(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """A smooth deformation-like pattern: ideal (rho/R)^2 times a few per mille modulation."""
    return ideal_go_intensity(theta, F, R, D) * (1.0 + 4e-3 * np.cos(2 * theta) * np.sin(phi)
                                                + 2e-3 * np.cos(3 * phi) * np.sin(theta))


def write_field(path: Path, grid: SphereGrid, values: np.ndarray | None = None) -> Path:
    """A synthetic GO FieldMap on ``grid`` (``pattern`` unless values are given)."""
    t, p = np.meshgrid(grid.theta, grid.phi, indexing="ij")
    ideal = ideal_go_intensity(t, F, grid.radius, D)
    save(fieldmap(grid, pattern(t, p) if values is None else values, ideal, focal_length=F,
                  diameter=D, frequency_hz=3e8, method="go", sampling="cell_mean"), path)
    return path


@pytest.fixture
def fine_field(tmp_path: Path) -> Path:
    """The pattern on a 2 deg x 4 deg grid over the whole hemisphere."""
    return write_field(tmp_path / "field.nc", SphereGrid(R, 45, 90))


@pytest.fixture
def raysim_main(raysim_cli):
    """The in-process runner of tests/conftest.py: ``code, out, err = raysim_main(*args)``."""
    return raysim_cli
