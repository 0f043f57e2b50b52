"""The number a learned inverse has to beat: the project's own inversion on a validation split.

For every validation sample of a dataset store, the FieldMap of the sample (the clean
intensity, and the measured one when the store has measurement effects) goes through
:func:`solver.invert` as a user would run it (the Poisson solve with zero rim, then the GO
model-based refinement; gain from the power balance) on the store's own aperture grid, and
the recovered surface is compared with the stored truth: RMS error over the aperture (m), the
same after removing piston, tilt and focus from both (what the intensity cannot see without
rim targets or an absolute calibration), the RMS of the error's part that is not harmonic
(the error less its least-squares fit by r^n cos(n phi), r^n sin(n phi), n <= 12: the
harmonic part is what zero-rim inversion cannot observe, and a learned inverse may learn it
from the training set's prior), RRMS (RMS / peak-to-peak of the truth), and the wall time
per sample. Nothing is trained here.

    python benchmarks/bench_baseline.py [--store STORE.zarr] [--samples 20] [--json out.json]

Without a store (``--store`` absent or not there yet) it first makes one of the paper's dish
(D = 110 m, F = 33 m, R = 10 m, 90 x 360 cells, 0.15 m mesh) with the error models of
``bench_dataset.py`` and a set of measurement effects (0.01 dB readings, two per point,
0.2 dB unknown gain, 0.5 mm centre offsets, up to 0.005 dB of uncorrected drift, 0.2 %
missing points) on two local workers.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_dataset import SPEC, save  # this folder is on sys.path when the script runs

MEASUREMENT = """
[measurement]
noise_db = 0.01
readings = 2
gain_db = { normal = [0.0, 0.2] }
centre_offset_mm = { normal = [0.0, 0.5] }
drift_db = { uniform = [0.0, 0.005] }
drift_period_points = { loguniform = [5000.0, 50000.0] }
missing_fraction = 0.002
"""


HARMONIC_ORDER = 12


def non_harmonic_rms(x: np.ndarray, error: np.ndarray, radius: float) -> float:
    """RMS (m) over the aperture of ``error`` (N, N) less its least-squares harmonic part."""
    X, Y = np.meshgrid(x, x)
    inside = (np.hypot(X, Y) < radius) & np.isfinite(error)
    z = (X[inside] + 1j * Y[inside]) / radius
    basis = [np.ones(z.size)]
    for n in range(1, HARMONIC_ORDER + 1):
        basis += [(z**n).real, (z**n).imag]
    A = np.column_stack(basis)
    e = error[inside]
    residual = e - A @ np.linalg.lstsq(A, e, rcond=None)[0]
    return float(np.sqrt(np.mean(residual**2)))


def invert_sample(ds, index: int, source: str, refine: int) -> dict[str, float]:
    """Invert one stored sample; its errors against the stored truth and its wall time."""
    from raysim.dataset import sample_fieldmap
    from solver.invert import invert

    field = sample_fieldmap(ds, index, source)
    truth = ds["deformation"].isel(sample=index).values
    start = time.perf_counter()
    surface = invert(field, N=truth.shape[0], truth=truth, refine_iterations=refine,
                     remove="piston,tilt,focus")
    seconds = time.perf_counter() - start
    a = surface.attrs
    observable = non_harmonic_rms(surface["x"].values, surface["error"].values, 0.5 * float(a["diameter"]))
    return {"sample": index, "rms_m": float(a["rms_before_removal_m"]), "rms_non_harmonic_m": observable,
            "rms_removed_m": float(a["rms_m"]), "rrms": float(a["rms_before_removal_m"])
            / float(a["truth_peak_to_peak_m"]), "rrms_removed": float(a["rrms"]),
            "seconds": seconds}


def summarise(rows: list[dict[str, float]]) -> dict[str, float]:
    out: dict[str, float] = {"samples": len(rows)}
    for key in ("rms_m", "rms_removed_m", "rms_non_harmonic_m", "rrms", "rrms_removed", "seconds"):
        values = np.array([r[key] for r in rows])
        out[f"{key}_median"] = float(np.median(values))
        out[f"{key}_mean"] = float(np.mean(values))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--store", type=Path, default=None,
                        help="a dataset store (made here, and kept, if it does not exist)")
    parser.add_argument("--samples", type=int, default=20, help="samples of the store made here")
    parser.add_argument("--refine", type=int, default=3, help="refinement iterations of the inversion")
    parser.add_argument("--limit", type=int, default=None, help="at most this many validation samples")
    parser.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = parser.parse_args()
    os.environ.setdefault("RAYSIM_THREADS", "1")
    from raysim.dataset import generate, open_dataset
    from raysim.dataset.loader import samples
    from raysim.dataset.store import open_readonly

    folder = Path(tempfile.mkdtemp(prefix="bench_baseline_"))
    try:
        store = args.store or folder / "baseline.zarr"
        if not store.exists():  # made here (and kept when --store names it)
            spec = folder / "baseline.toml"
            spec.write_text(SPEC.format(samples=args.samples) + MEASUREMENT)
            print(generate(spec, store, workers=2).summary())
        ds = open_dataset(store)
        validation = samples(open_readonly(str(store)), "validation")[: args.limit]
        sources = ["clean"] + (["measured"] if "intensity_measured" in ds.data_vars else [])
        print(f"{len(validation)} validation samples; load average {os.getloadavg()}")
        results: dict[str, object] = {"store": str(store), "refine": args.refine}
        for source in sources:
            rows = [invert_sample(ds, int(i), source, args.refine) for i in validation]
            results[source] = {"summary": summarise(rows), "samples": rows}
            s = results[source]["summary"]
            print(f"{source}: RMS error {s['rms_m_median'] * 1e6:.2f} um median "
                  f"({s['rms_m_mean'] * 1e6:.2f} mean), RRMS {100 * s['rrms_median']:.2f} %; after "
                  f"removing piston, tilt, focus {s['rms_removed_m_median'] * 1e6:.2f} um, "
                  f"RRMS {100 * s['rrms_removed_median']:.2f} %; non-harmonic part "
                  f"{s['rms_non_harmonic_m_median'] * 1e6:.2f} um; "
                  f"{s['seconds_median']:.2f} s per sample (median)")
        save(results, args.json)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
