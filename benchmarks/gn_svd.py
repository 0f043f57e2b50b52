"""What the 0.1 GHz data can determine: singular values of the exact PO + PTD Jacobian.

On the paper's dish at the Eq. 8 surface, the Jacobian of the refinement's weighted misfit
(:mod:`solver.gauss_newton`: r = w (... - I0 / I), dr = w I0 / I^2 dI) restricted to
axially symmetric shapes: cubic B-splines in r on [0, D/2] that vanish on the rim (the
paper's boundary assumption), one JVP each. Its singular values s_i, set against the noise
each residual carries (0.01 dB per sample: sigma = 0.01 ln(10) / 10 in I, times w), give the
precision noise / s_i (m) with which the data fix each singular shape; shapes whose precision
is worse than the shape's share of the deformation are what the data cannot determine.

    nice -n 10 .venv/bin/python benchmarks/gn_svd.py --frequency 0.1e9 --sphere 45x90
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.interpolate import BSpline

sys.path.insert(0, str(Path(__file__).resolve().parent))

import gn_data

from raysim.maps.sphere import SphereGrid
from solver.aperture import ApertureGrid
from solver.forward import WaveForward
from solver.jacobian import WaveJacobian
from solver.resample import usable_rows
from solver.wave import amplitude_weight


def radial_basis(grid: ApertureGrid, n: int) -> np.ndarray:
    """(n, n_inside) cubic B-splines in r over [0, a], the ones not vanishing at r = a dropped."""
    a = grid.a
    inner = np.linspace(0.0, a, n + 1)
    t = np.concatenate([[0.0] * 3, inner, [a] * 3])
    r = grid.r[grid.mask]
    B = BSpline.design_matrix(np.minimum(r, a), t, 3).toarray()  # (n_inside, n + 3)
    keep = [j for j in range(B.shape[1]) if abs(B[np.argmax(r), j]) < 1e-9]
    return B[:, keep].T


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frequency", type=float, default=0.1e9)
    ap.add_argument("--sphere", default="45x90")
    ap.add_argument("--basis", type=int, default=30)
    ap.add_argument("--grid", type=int, default=128)
    args = ap.parse_args()
    n_theta, n_phi = (int(v) for v in args.sphere.split("x"))
    D, F, R = gn_data.D, gn_data.F, gn_data.R
    sphere = SphereGrid(R, n_theta, n_phi)
    grid = ApertureGrid(D, args.grid)
    X, Y = grid.XY
    truth = grid.masked(gn_data.paper_deformation()(X, Y))
    model = WaveForward(args.frequency, ptd=True)
    start = time.perf_counter()
    jac = WaveJacobian(model, sphere, F, D, grid, truth)
    I0 = model(sphere, F, D, grid.x, grid.y, None)
    I = jac.intensity
    w = amplitude_weight(I0, sphere, F, "centre")
    rows = np.zeros(I.shape, dtype=bool)
    rows[:usable_rows(sphere, F, D)] = True
    scale = (w * I0 / I**2)[rows]
    basis = radial_basis(grid, args.basis)
    J = np.stack([scale * jac.jvp(b)[rows] for b in basis], axis=1)  # residual per m
    _, s, Vt = np.linalg.svd(J, full_matrices=False)
    sigma = 0.01 * np.log(10.0) / 10.0
    noise = sigma * float(np.sqrt(np.mean(w[rows] ** 2)))
    coef_truth = np.linalg.lstsq(basis.T, truth[grid.mask], rcond=None)[0]
    share = Vt @ coef_truth  # the truth's component along each right singular vector
    shapes = Vt @ basis      # singular shapes on the grid (unit coefficient norm)
    amp = np.sqrt(np.mean(shapes**2, axis=1))  # RMS (m) of each shape per unit coefficient
    out = {"frequency_hz": args.frequency, "sphere": args.sphere, "basis": len(basis),
           "seconds": time.perf_counter() - start, "noise_per_residual": noise,
           "singular_values": s.tolist(),
           "precision_rms_um": (noise / s * amp * 1e6).tolist(),
           "truth_rms_um_per_shape": (np.abs(share) * amp * 1e6).tolist()}
    print(json.dumps(out), flush=True)
    with open(gn_data.OUT / "svd.jsonl", "a") as fh:
        fh.write(json.dumps(out) + "\n")
    for i, (sv, p, t) in enumerate(zip(s, out["precision_rms_um"], out["truth_rms_um_per_shape"],
                                       strict=True)):
        print(f"{i:3d} s = {sv:.3e} per m   precision {p:9.3f} um   truth's part {t:9.3f} um")


if __name__ == "__main__":
    main()
