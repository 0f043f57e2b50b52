"""Table 3 with the Gauss-Newton refinement: today's wave refinement and Gauss-Newton side by side.

Data: PO + PTD FieldMaps made by a finer model than the inversion's (4 m faces, 3 samples per
wavelength, 8 edge points per wavelength against 5 m, 1.5 and 4; ``benchmarks/gn_data.py``),
cached under ``out/gauss_newton/``; each case also with 0.01 dB Gaussian noise per sample.
For each (frequency, deformation, noise) it inverts twice on the same data at N = 256: the
defect-correction wave refinement (``--refine-method defect``) and the same followed by
Gauss-Newton with the exact PO + PTD Jacobian (``gauss-newton``; ``--methods auto`` runs
``raysim invert``'s default, which fits the steps to its budget), and prints RRMS, RMS, steps,
LSQR iterations and time; rows are appended to ``out/gauss_newton/results.jsonl``.

    nice -n 10 .venv/bin/python benchmarks/bench_gauss_newton.py --frequencies 0.1e9 \
        --deformation paper --noise 0,0.01

Each LSQR iteration is a JVP and a VJP of the model. The model sums with the fast radiator
(its default), and on the full 90 x 360 grid on two cores an iteration takes about 1.3 s at
0.1 GHz, 5 s at 0.3 GHz, 18 s at 0.6 GHz and 40 to 60 s at 1 GHz; so the default 3 steps of up
to 60 iterations take about 4 min at 0.1 GHz.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import gn_data

from solver.gauss_newton import GaussNewtonOptions
from solver.invert import invert


def run_case(frequency_hz: float, name: str, noise_db: float, N: int,
             options: GaussNewtonOptions, methods: tuple[str, ...],
             sphere: tuple[int, int] = (90, 360)) -> list[dict]:
    field = gn_data.fine_fieldmap(frequency_hz, name, *sphere, log=lambda s: print(s, flush=True))
    if noise_db > 0:
        field = gn_data.with_noise(field, noise_db)
    truth = gn_data.DEFORMATIONS[name]()
    rim = gn_data.rim_targets(truth) if name == "second" else None
    rows = []
    for method in methods:
        start = time.perf_counter()
        result = invert(field, N=N, truth=truth, rim=rim, refine_method=method,
                        gauss_newton=options, log=lambda s: print(f"  {s}", flush=True))
        a = result.attrs
        row = {"frequency_hz": frequency_hz, "deformation": name, "noise_db": noise_db,
               "method": method, "N": N, "rrms": float(a["rrms"]), "rms_um": float(a["rms_m"]) * 1e6,
               "seconds": time.perf_counter() - start,
               "defect_iterations": int(a["refine_iterations"]),
               "gn_steps": len(str(a.get("gn_step_factor", "")).split(",")) if a.get("gn_used") else 0,
               "gn_lsqr": str(a.get("gn_lsqr_iterations", "")), "gn_misfit": str(a.get("gn_misfit_rms", "")),
               "gn_stopped": str(a.get("gn_stopped", "")), "gn_noise": float(a.get("gn_noise_rms", 0.0)),
               "rim_targets": 0 if rim is None else len(rim), "sphere": f"{sphere[0]}x{sphere[1]}",
               "gn_jvp_calls": int(a.get("gn_jvp_calls", 0)), "gn_vjp_calls": int(a.get("gn_vjp_calls", 0)),
               "gn_coarse_steps": int(a.get("gn_coarse_steps", 0))}
        rows.append(row)
        print(json.dumps(row), flush=True)
        with open(gn_data.OUT / "results.jsonl", "a") as fh:
            fh.write(json.dumps(row) + "\n")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frequencies", default="0.1e9")
    ap.add_argument("--deformation", default="paper", choices=sorted(gn_data.DEFORMATIONS))
    ap.add_argument("--noise", default="0,0.01", help="dB per sample, comma-separated")
    ap.add_argument("--methods", default="defect,gauss-newton")
    ap.add_argument("--grid", type=int, default=256)
    ap.add_argument("--sphere", default="90x360", help="n_theta x n_phi of the scan")
    ap.add_argument("--steps", type=int, default=GaussNewtonOptions.iterations)
    ap.add_argument("--inner", type=int, default=GaussNewtonOptions.inner)
    ap.add_argument("--coarse", type=int, default=GaussNewtonOptions.coarse,
                    help="first steps whose LSQR runs on one cell in eight")
    args = ap.parse_args()
    options = GaussNewtonOptions(iterations=args.steps, inner=args.inner, coarse=args.coarse)
    for f in (float(v) for v in args.frequencies.split(",")):
        for noise in (float(v) for v in args.noise.split(",")):
            run_case(f, args.deformation, noise, args.grid, options,
                     tuple(args.methods.split(",")),
                     tuple(int(n) for n in args.sphere.lower().split("x")))


if __name__ == "__main__":
    main()
