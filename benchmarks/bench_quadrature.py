"""PO's quadrature on the paper's dish: the rule that follows the integrand's own rate against the
uniform rule, both against a finer uniform one.

Run: ``python benchmarks/bench_quadrature.py [--freqs 0.3 1 3] [--points 300] [--fine 2.5]
[--integrand-tol 1e-9 1e-8] [--n-max 128] [--reference uniform|tight]``.

For each frequency: the PO elements of the ideal dish (D 110 m, F 33 m, 5 m faces, plane wave
along the axis) radiated by the direct sum to ``--points`` points spread over the 90 x 360 sphere
grid (R 10 m about the focus), from three quadratures: the reference, the uniform rule at 1.5,
and the rule on the integrand's rate with each ``--integrand-tol`` value (each face's Gauss error
on the integrand's phase, its rules of order up to ``--n-max``; the targets are the whole
grid's ball). The reference: ``--fine`` samples per wavelength on every face (``uniform``), or
(``tight``) the integrand's rate held to 1e-13 per face on orders up to 24, never more points
on a face than ``--fine`` per wavelength: other points than the rule's, and no uniform rule's
own error at high frequency (at 3 GHz the uniform rules at 1.5 and 2.5 differ by 3.9e-7).
Prints the samples and the relative RMS difference of E from the reference.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def main() -> None:
    from raysim.maps.sphere import SphereGrid
    from raysim.optics import po
    from raysim.optics.radiator import Radiator
    from raysim.surface import quadrature
    from raysim.surface.mesh import paraboloid

    ap = argparse.ArgumentParser()
    ap.add_argument("--freqs", type=float, nargs="+", default=[0.3, 1.0, 3.0])
    ap.add_argument("--points", type=int, default=300)
    ap.add_argument("--fine", type=float, default=2.5)
    ap.add_argument("--integrand-tol", type=float, nargs="+", default=[quadrature.INTEGRAND_TOL])
    ap.add_argument("--n-max", type=int, default=quadrature.INTEGRAND_N_MAX)
    ap.add_argument("--reference", choices=("uniform", "tight"), default="uniform")
    args = ap.parse_args()
    defaults = quadrature.INTEGRAND_N_MAX, quadrature.INTEGRAND_TOL
    dish = paraboloid(110.0, 33.0, 5.0)
    grid = SphereGrid(10.0, 90, 360).points(33.0).reshape(-1, 3)
    points = grid[np.linspace(0, len(grid) - 1, args.points).astype(int)]
    print("| f (GHz) | rule | samples | rel. RMS difference of E | seconds |")
    print("| --- | --- | --- | --- | --- |")
    for f in args.freqs:
        wave = po.Illumination.plane_wave(f * 1e9, (0, 0, -1), (1, 0, 0))
        targets = quadrature.targets_around(grid, (0.0, 0.0, 33.0), wave.k_hat)

        def field(q: quadrature.FaceQuadrature, wave: po.Illumination = wave) -> np.ndarray:
            radiator = Radiator(points, wave.k)
            for chunk in po.po_elements(dish, wave, q):
                radiator.add_packed(chunk.numpy(), "electric")
            return radiator.field()

        start = time.perf_counter()
        if args.reference == "tight":
            quadrature.INTEGRAND_N_MAX, quadrature.INTEGRAND_TOL = 24, 1e-13
            fine = quadrature.plan(dish, wave.wavelength, args.fine, targets)
            name = f"integrand's rate, 1e-13 per face, orders up to 24, at most {args.fine:g} per wavelength"
        else:
            fine = quadrature.plan(dish, wave.wavelength, args.fine)
            name = f"uniform, {args.fine:g} per wavelength"
        quadrature.INTEGRAND_N_MAX, quadrature.INTEGRAND_TOL = defaults
        ref = field(fine)
        print(f"| {f:g} | {name} (reference) | {fine.n_samples:,} | | "
              f"{time.perf_counter() - start:.1f} |", flush=True)
        rules = [("uniform, 1.5 per wavelength", quadrature.plan(dish, wave.wavelength, 1.5))]
        quadrature.INTEGRAND_N_MAX = args.n_max
        for tol in args.integrand_tol:
            quadrature.INTEGRAND_TOL = tol
            rules.append((f"integrand's rate, {tol:g} per face, orders up to {args.n_max}",
                          quadrature.plan(dish, wave.wavelength, 1.5, targets)))
        for name, q in rules:
            start = time.perf_counter()
            E = field(q)
            err = float(np.sqrt(np.mean(np.abs(E - ref) ** 2) / np.mean(np.abs(ref) ** 2)))
            print(f"| {f:g} | {name} | {q.n_samples:,} | {err:.1e} | {time.perf_counter() - start:.1f} |",
                  flush=True)


if __name__ == "__main__":
    main()
