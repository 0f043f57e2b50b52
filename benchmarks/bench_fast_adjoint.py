"""The PO Jacobian's VJP by the fast (multilevel) transposed sum against the direct one, on the
paper's dish (D 110 m, F 33 m, sphere R 10 m about the focus).

Run: ``python benchmarks/bench_fast_adjoint.py [--freqs 0.1 0.3] [--grid 90 360] [--tol 1e-6]
[--curve] [--plot PNG]``. For each frequency: the PO samples of the ideal dish (default sampling, 1.5 a
wavelength), random complex weights on the sphere grid, the gradients (dz, dh_x, dh_y) by
``po_jacobian.vjp`` with ``radiator="fast"`` (tolerance ``--tol``; the cost rule decides, as the
solver would see it) and with the direct sum, the wall time of each (kernels warmed up first)
and the relative RMS difference of the dz and dh_x gradients. ``--curve``: error against
tolerance at the first frequency (multilevel sum forced). ``--plot``: the times (and the curve)
as a PNG.

Measured (``--freqs 0.1 0.3``, tolerance 1e-6) on the two cores while a 3 GHz simulation and
the test suite shared them, so both columns are slow by the same factor:

| f (GHz) | PO samples | fast VJP (s) | direct VJP (s) | rel. RMS dz / dh_x | plan |
| --- | --- | --- | --- | --- | --- |
| 0.1 | 11,074 | 1.0 | 14.1 | 8.8e-9 / 6.8e-9 | levels 3..4, grids 66..42, series on the grid |
| 0.3 | 80,331 | 11.1 | 105.1 | 6.5e-8 / 4.2e-8 | levels 3..6, grids 140..36, series on the grid |

With the transposed sums' pairs in vector lanes (5 December 2026, idle cores; the kernels
before them measured just before on the same cores in brackets): 0.1 GHz fast 0.6 s (0.7),
direct 3.9 s (9.7); 0.3 GHz fast 2.8 s (3.7), direct 30.5 s (68.4); the same plans and errors.
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
    ap.add_argument("--plot", type=Path, default=None)
    args = ap.parse_args()
    el, pts, c = problem(0.1, (6, 12))  # warm-up: compile or load the kernels
    fast(el, pts, c, args.tol, True)
    po_jacobian.vjp(el, pts, c)
    print("| f (GHz) | PO samples | points | fast VJP (s) | direct VJP (s) | rel. RMS dz | rel. RMS dh_x "
          "| plan |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    ref = {}
    rows, curve = [], []
    for f in args.freqs:
        el, pts, c = problem(f, tuple(args.grid))
        g, t_fast, method = fast(el, pts, c, args.tol, False)
        start = time.perf_counter()
        d = po_jacobian.vjp(el, pts, c)
        t_direct = time.perf_counter() - start
        ref[f] = (el, pts, c, d)
        rows.append((f, len(el), t_fast, t_direct))
        print(f"| {f:g} | {len(el):,} | {len(pts):,} | {t_fast:.1f} | {t_direct:.1f} | {rel(g[0], d[0]):.1e} "
              f"| {rel(g[1], d[1]):.1e} | {method} |", flush=True)
    if args.curve:
        el, pts, c, d = ref[args.freqs[0]]
        print("\n| tol | rel. RMS dz | rel. RMS dh_x | fast VJP (s) | plan |")
        print("| --- | --- | --- | --- | --- |")
        for tol in (1e-2, 1e-4, 1e-6, 1e-8):
            g, t, method = fast(el, pts, c, tol, True)
            curve.append((tol, rel(g[0], d[0]), rel(g[1], d[1])))
            print(f"| {tol:.0e} | {rel(g[0], d[0]):.1e} | {rel(g[1], d[1]):.1e} | {t:.1f} | {method} |",
                  flush=True)
    if args.plot is not None:
        plot(args.plot, rows, curve, tuple(args.grid))


def plot(path: Path, rows: list, curve: list, grid: tuple[int, int]) -> None:
    """Times of the fast and direct VJP against frequency; the error curve beside, if run."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    fig, axes = plt.subplots(1, 2 if curve else 1, figsize=(10 if curve else 5, 4), squeeze=False,
                             layout="constrained")
    ax = axes[0, 0]
    f = [r[0] for r in rows]
    ax.plot(f, [r[3] for r in rows], "o-", label="direct transposed sum")
    ax.plot(f, [r[2] for r in rows], "s-", label="fast (multilevel) transposed sum")
    ax.set(xscale="log", yscale="log", xlabel="frequency (GHz), PO samples",
           ylabel="wall time (s, two cores)",
           title=f"PO Jacobian VJP, D 110 m dish, {grid[0]} x {grid[1]} points")
    ax.set_xticks(f, [f"{r[0]:g}\n{r[1]:,}" for r in rows])
    ax.xaxis.set_minor_formatter(NullFormatter())
    ticks = [t for t in (0.5, 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000)
             if min(r[2] for r in rows) / 2 <= t <= max(r[3] for r in rows) * 2]
    ax.set_yticks(ticks, [f"{t:g}" for t in ticks])
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.margins(x=0.15, y=0.15)
    ax.legend(loc="lower right")
    if curve:
        ax = axes[0, 1]
        ax.loglog([c[0] for c in curve], [c[1] for c in curve], "o-", label="dz gradient")
        ax.loglog([c[0] for c in curve], [c[2] for c in curve], "s-", label="dh_x gradient")
        ax.loglog([c[0] for c in curve], [c[0] for c in curve], "k:", label="tolerance")
        ax.set(xlabel="--radiator-tol", ylabel="relative RMS against the direct VJP",
               title=f"error against tolerance, {rows[0][0]:g} GHz")
        ax.legend()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
