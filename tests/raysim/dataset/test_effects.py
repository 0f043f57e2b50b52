"""Measurement effects: each one against what the scan physics says it must do."""

from __future__ import annotations

import math

import numpy as np
import pytest

from raysim.dataset import DatasetError, load_spec, open_dataset, parse_spec
from raysim.dataset import effects as fx
from raysim.dataset.reading import sample_measured
from raysim.maps.sphere import SphereGrid, ideal_go_intensity
from tests.raysim.dataset.conftest import ROOT, small_demo_text

F, D, R = 33.0, 110.0, 10.0
GRID = SphereGrid(R, 60, 180)
SHAPE = (GRID.n_theta, GRID.n_phi)
NONE = {"noise_db": 0.0, "readings": 1, "gain_db": 0.0, "offset_x": 0.0, "offset_y": 0.0,
        "offset_z": 0.0, "drift_db": 0.0, "drift_period": 1e4, "drift_phase": 0.0,
        "missing_fraction": 0.0}


def _ideal_point_values(grid: SphereGrid) -> np.ndarray:
    theta = np.repeat(grid.theta[:, None], grid.n_phi, axis=1)
    return ideal_go_intensity(theta, F, grid.radius, D)


def _apply(clean, values, seed=0):
    return fx.apply(clean, _ideal_point_values(GRID), GRID, F, D, {**NONE, **values},
                    np.random.default_rng(seed))


def test_without_effects_the_measured_intensity_is_the_clean_one():
    clean = _ideal_point_values(GRID) * (1.0 + 1e-3 * np.random.default_rng(1).standard_normal(SHAPE))
    assert _apply(clean, {}).tobytes() == clean.tobytes()


def test_gain_scales_the_scan_and_readings_average_the_noise():
    clean = _ideal_point_values(GRID)
    lit = clean > 0
    assert np.allclose(_apply(clean, {"gain_db": 0.5})[lit] / clean[lit], 10 ** 0.05, rtol=1e-14, atol=0)
    sigma, k = 0.05, 4
    ratio = _apply(clean, {"noise_db": sigma, "readings": k})[lit] / clean[lit]
    # each reading is 10^(s z / 10), z standard normal: a log-normal of log-sd b = s ln10 / 10
    b = sigma * math.log(10.0) / 10.0
    mean, sd = math.exp(0.5 * b * b), math.sqrt((math.exp(b * b) - 1.0) * math.exp(b * b) / k)
    n = ratio.size
    assert abs(ratio.mean() - mean) < 5 * sd / math.sqrt(n)
    assert ratio.std() == pytest.approx(sd, rel=0.03)


def test_drift_follows_the_scan_order():
    clean = np.ones(SHAPE)
    amplitude, period = 0.02, 700.0
    ratio = _apply(clean, {"drift_db": amplitude, "drift_period": period, "drift_phase": 1.0})
    # the rig sweeps theta up on even phi lines and down on odd ones
    line0, line1 = ratio[:, 0], ratio[::-1, 1]
    sequence = np.concatenate([line0, line1])
    assert sequence[0] == 1.0  # no drift at the scan's start
    db = 10.0 * np.log10(sequence)
    assert np.all(np.abs(db) <= 2 * amplitude + 1e-12)
    step = 2.0 * np.pi / period  # d(drift)/dn at the start: A cos(p) 2 pi / P
    assert db[1] == pytest.approx(amplitude * math.cos(1.0) * step, rel=1e-2)
    # one period later the drift repeats
    flat = np.empty(GRID.n_theta * GRID.n_phi)
    order = np.concatenate([np.arange(GRID.n_theta) if j % 2 == 0 else np.arange(GRID.n_theta)[::-1]
                            for j in range(GRID.n_phi)])
    flat[:] = ratio[order, np.repeat(np.arange(GRID.n_phi), GRID.n_theta)]
    assert np.allclose(flat[700:1400], flat[:700], rtol=1e-12)


def test_a_displaced_track_reads_the_field_where_the_probe_really_is():
    clean = _ideal_point_values(GRID)
    offset = (0.004, -0.002, 0.006)
    measured = _apply(clean, {"offset_x": offset[0], "offset_y": offset[1], "offset_z": offset[2]})
    # the probe believed at (theta, phi) on radius R sits at c + R u; the ideal paraboloid's
    # GO intensity there is (rho(theta') / r)^2, r its distance from the focus
    theta, phi = np.meshgrid(GRID.theta, GRID.phi, indexing="ij")
    u = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), -np.cos(theta)])
    p = np.asarray(offset)[:, None, None] + R * u
    r = np.linalg.norm(p, axis=0)
    theta_true = np.arccos(-p[2] / r)
    expected = (2.0 * F / (1.0 + np.cos(theta_true)) / r) ** 2
    inner = theta < np.radians(75.0)
    assert np.allclose(measured[inner], expected[inner], rtol=1e-12)
    assert np.max(np.abs(measured[inner] / clean[inner] - 1.0)) > 1e-4  # a visible effect


def test_missing_points_are_nan_at_the_drawn_rate():
    clean = _ideal_point_values(GRID)
    measured = _apply(clean, {"missing_fraction": 0.05}, seed=4)
    lost = np.isnan(measured)
    n = lost.size
    assert abs(lost.mean() - 0.05) < 5 * math.sqrt(0.05 * 0.95 / n)
    assert np.array_equal(measured[~lost], clean[~lost])


@pytest.mark.parametrize("table, message", [
    ("typo_db = 1.0", "unknown key 'measurement.typo_db'"),
    ("noise_db = -0.1", "'measurement.noise_db' must stay >= 0"),
    ("readings = 1.5", "'measurement.readings' must be an integer"),
    ("missing_fraction = { uniform = [0.0, 0.9] }", "'measurement.missing_fraction' must stay <= 0.5"),
])
def test_measurement_defects_raise_one_line(table, message):
    text = small_demo_text(measurement=False) + f"\n[measurement]\n{table}\n"
    with pytest.raises(DatasetError, match=message.replace("[", r"\[").replace("(", r"\(")):
        parse_spec(text, base=ROOT / "scenes")


@pytest.mark.slow
def test_stored_effects_are_the_drawn_ones_and_regenerate(measured_store, monkeypatch):
    spec, path = measured_store
    ds = open_dataset(path)
    law = spec.measurement
    for name, dist in (("noise_db", law.noise_db), ("missing_fraction", law.missing_fraction)):
        values = ds[f"measure_{name}"].values
        assert np.all((values >= dist.support[0]) & (values <= dist.support[1]))
    assert set(ds["measure_readings"].values) <= {1, 2, 3}
    assert np.all(np.abs(ds["measure_offset_x"].values) < 0.01)  # mm law stored in m
    measured, clean = ds["intensity_measured"].values, ds["intensity"].values
    lit = ds["intensity_ideal"].values[0] > 1.0
    for i in range(spec.samples):
        ratio = measured[i][lit] / clean[i][lit]
        gain = 10 ** (float(ds["measure_gain_db"][i]) / 10)
        assert np.nanmedian(ratio) == pytest.approx(gain, rel=0.01)
    monkeypatch.setenv("RAYSIM_THREADS", "1")
    again = sample_measured(load_spec_from(ds), 4)
    assert np.array_equal(again, measured[4], equal_nan=True)


def load_spec_from(ds):
    """The spec a store was made from, from its attributes."""
    return parse_spec(ds.attrs["spec"], source=ds.attrs["spec_source"], base=ROOT / "scenes")


def test_a_store_without_effects_has_no_measured_intensity(tmp_path):
    from raysim.dataset import store as zstore
    from raysim.dataset.reading import sample_fieldmap

    spec = load_spec(ROOT / "scenes" / "dataset_demo.toml")
    group = zstore.create(str(tmp_path / "plain.zarr"), spec)
    assert "intensity_measured" not in group and not any(k.startswith("measure_") for k in group)
    with pytest.raises(DatasetError, match="no measured intensity"):
        sample_fieldmap(open_dataset(tmp_path / "plain.zarr"), 0, "measured")


def test_the_demo_specs_commented_measurement_table_is_valid():
    text = (ROOT / "scenes" / "dataset_demo.toml").read_text()
    head, _, tail = text.partition("# [measurement]")
    lines = ["[measurement]"] + [line[2:] for line in tail.splitlines() if line.startswith("# ") and "=" in line]
    spec = parse_spec(head + "\n".join(lines) + "\n", base=ROOT / "scenes")
    assert spec.measurement is not None and spec.measurement.readings.support == (1.0, 4.0)
    assert spec.measurement.centre_offset.b == pytest.approx(1e-3)  # mm in the file, m inside
