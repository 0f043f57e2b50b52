"""The PO Jacobian's VJP by the fast (multilevel) transposed sum against the direct one, on the
paper's dish (D 110 m, F 33 m, sphere R 10 m about the focus).

Run: ``python benchmarks/bench_fast_adjoint.py [--freqs 0.1 0.3] [--grid 90 360] [--tol 1e-6]
[--curve]``. For each frequency: the PO samples of the ideal dish (default sampling, 1.5 a
wavelength), random complex weights on the sphere grid, the gradients (dz, dh_x, dh_y) by
``po_jacobian.vjp`` with ``radiator="fast"`` (tolerance ``--tol``; the cost rule decides, as the
solver would see it) and with the direct sum, the wall time of each (kernels warmed up first)
and the relative RMS difference of the dz and dh_x gradients. ``--curve``: error against
tolerance at the first frequency (multilevel sum forced).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
CENTRE = (0.0, 0.0, 33.0)


def problem(freq_ghz: float, grid_shape: tuple[int, int]):
    from raysim.maps.sphere import SphereGrid
    from raysim.optics import po, po_jacobian
    from raysim.optics.illumination import Illumination
    from raysim.surface.mesh import paraboloid

    wave = Illumination.plane_wave(freq_ghz * 1e9, (0, 0, -1), (1, 0, 0))
    elements = po_jacobian.surface_elements(paraboloid(110.0, 33.0, 5.0), wave,
                                            po.DEFAULT_SAMPLES_PER_WAVELENGTH, "cpu")
    pts = SphereGrid(10.0, *grid_shape).points(33.0).reshape(-1, 3)
    rng = np.random.default_rng(1)
    c = rng.standard_normal((len(pts), 3)) + 1j * rng.standard_normal((len(pts), 3))
    return elements, pts, c


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.sum((a - b) ** 2) / np.sum(b**2)))


def fast(elements, pts, c, tol: float, force: bool) -> tuple[tuple, float, str]:
    from raysim.optics import po_jacobian

    info: dict = {}
    start = time.perf_counter()
    g = po_jacobian.vjp(elements, pts, c, radiator="fast", tol=tol, centre=CENTRE, force=force, info=info)
    return g, time.perf_counter() - start, info["method"]


def main() -> None:
    from raysim.optics import po_jacobian

    ap = argparse.ArgumentParser()
    ap.add_argument("--freqs", type=float, nargs="+", default=[0.1, 0.3])
    ap.add_argument("--grid", type=int, nargs=2, default=[90, 360])
    ap.add_argument("--tol", type=float, default=1e-6)
    ap.add_argument("--curve", action="store_true")
    args = ap.parse_args()
    el, pts, c = problem(0.1, (6, 12))  # warm-up: compile or load the kernels
    fast(el, pts, c, args.tol, True)
    po_jacobian.vjp(el, pts, c)
    print("| f (GHz) | PO samples | points | fast VJP (s) | direct VJP (s) | rel. RMS dz | rel. RMS dh_x "
          "| plan |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    ref = {}
    for f in args.freqs:
        el, pts, c = problem(f, tuple(args.grid))
        g, t_fast, method = fast(el, pts, c, args.tol, False)
        start = time.perf_counter()
        d = po_jacobian.vjp(el, pts, c)
        t_direct = time.perf_counter() - start
        ref[f] = (el, pts, c, d)
        print(f"| {f:g} | {len(el):,} | {len(pts):,} | {t_fast:.1f} | {t_direct:.1f} | {rel(g[0], d[0]):.1e} "
              f"| {rel(g[1], d[1]):.1e} | {method} |", flush=True)
    if args.curve:
        el, pts, c, d = ref[args.freqs[0]]
        print("\n| tol | rel. RMS dz | rel. RMS dh_x | fast VJP (s) | plan |")
        print("| --- | --- | --- | --- | --- |")
        for tol in (1e-2, 1e-4, 1e-6, 1e-8):
            g, t, method = fast(el, pts, c, tol, True)
            print(f"| {tol:.0e} | {rel(g[0], d[0]):.1e} | {rel(g[1], d[1]):.1e} | {t:.1f} | {method} |",
                  flush=True)


if __name__ == "__main__":
    main()
