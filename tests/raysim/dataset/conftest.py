"""A small dataset with measurement effects, made once for the engine and loader tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from raysim.dataset import generate, parse_spec

ROOT = Path(__file__).resolve().parents[3]
DEMO_TEXT = (ROOT / "scenes" / "dataset_demo.toml").read_text()
MEASUREMENT = """
[measurement]
noise_db = { uniform = [0.005, 0.02] }
readings = { integers = [1, 3] }
gain_db = { normal = [0.0, 0.3] }
centre_offset_mm = { normal = [0.0, 1.0] }
drift_db = { uniform = [0.0, 0.01] }
drift_period_points = { loguniform = [500.0, 5000.0] }
missing_fraction = { uniform = [0.0, 0.02] }
"""


def small_demo_text(samples: int = 6, measurement: bool = True) -> str:
    """The demo spec on a 20 x 72 cell sphere with ``samples`` samples, 2 of them validation."""
    text = (DEMO_TEXT.replace("samples = 8", f"samples = {samples}")
            .replace("validation_fraction = 0.25", f"validation_fraction = {2 / samples}")
            .replace("n_theta = 30", "n_theta = 20").replace("n_phi = 120", "n_phi = 72"))
    return text + MEASUREMENT if measurement else text


@pytest.fixture(scope="session")
def measured_store(tmp_path_factory):
    """(spec, store path) of the small demo with measurement effects, made by one worker
    process of one thread (so that a sample regenerated here with RAYSIM_THREADS=1 matches)."""
    spec = parse_spec(small_demo_text(), source="small_demo.toml", base=ROOT / "scenes")
    path = tmp_path_factory.mktemp("measured") / "small.zarr"
    report = generate(spec, path, workers=1, threads=1)
    assert report.done == spec.samples and report.failed == 0
    return spec, path


@pytest.fixture(scope="module")
def inproc():
    """A Dask cluster inside this process (one worker thread, no network), for the quick runs.

    The dataset's worker plugin sets RAYSIM_THREADS=1 in the worker's process, here ours:
    it is restored afterwards.
    """
    from distributed import LocalCluster

    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("RAYSIM_THREADS", "1")
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                          dashboard_address=None) as cluster:
            yield cluster.scheduler_address
