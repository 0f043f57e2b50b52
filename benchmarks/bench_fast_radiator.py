"""Fast (multilevel) radiator against the direct sum on the paper's dish (D 110 m, F 33 m, R 10 m).

Run: ``python benchmarks/bench_fast_radiator.py [--freqs 0.1 0.3 1] [--grid 90 360] [--ptd]
[--tol 1e-6] [--ref-points N] [--curve] [--integrand]``. For each frequency: the PO elements of
the ideal dish (default sampling; ``--integrand``: the quadrature on the integrand's rate for
the grid's points, as ``raysim simulate`` makes them) radiated to the sphere grid by the fast
radiator (tolerance ``--tol``) and by the direct sum, wall time of each (kernels warmed up
first), the relative RMS error of E, and the process's peak memory so far. Beyond
:data:`FULL_PAIRS` element-point pairs the direct reference runs on ``--ref-points`` points
spread over the grid only (its time then extrapolated to the whole grid, marked ``~``);
``--ref-points 0`` makes it cover every point whatever the cost.
``--curve``: relative RMS error against tolerance at the first frequency (multilevel sum forced,
even where the direct sum would be chosen).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
FULL_PAIRS = 3e9  # the direct reference covers the whole grid up to this many pairs (about a minute)
REF_CHUNK = 4_000_000  # elements handed to the direct reference at once (0.3 GB)
sys.path.insert(0, str(ROOT))


def elements(freq_ghz: float, ptd: bool, targets=None):
    from raysim.optics import po
    from raysim.optics import ptd as ptd_mod
    from raysim.surface.mesh import paraboloid
    from raysim.surface.quadrature import plan

    wave = po.Illumination.plane_wave(freq_ghz * 1e9, (0, 0, -1), (1, 0, 0))
    dish = paraboloid(110.0, 33.0, 5.0)
    quad = plan(dish, wave.wavelength, po.DEFAULT_SAMPLES_PER_WAVELENGTH,
                None if targets is None else targets(wave))
    # the chunks as they come (no concatenated copy: at 12 GHz the elements are 8 GB)
    # made as they are read: at 12 GHz the elements are 8 GB, more than a batch
    out = {"electric": (chunk.numpy() for chunk in po.po_elements(dish, wave, quad))}
    if ptd:
        from raysim.surface.edges import edge_quadrature

        q = edge_quadrature(dish, wave.wavelength / ptd_mod.DEFAULT_POINTS_PER_WAVELENGTH, "rim")
        lit = ptd_mod.lit_points(dish, q, wave, "cpu")
        out["fringe"] = iter([np.asarray(ptd_mod.fringe_elements(q, wave, lit, None))])
    return wave, out, quad.n_samples


def run(freq: float, grid_shape: tuple[int, int], tol: float, ref_points: int, ptd: bool,
        force: bool = False, integrand: bool = False) -> dict:
    from raysim.maps.sphere import SphereGrid
    from raysim.optics.fast.radiator import FastRadiator
    from raysim.optics.radiator import Radiator
    from raysim.surface.quadrature import targets_around

    pts = SphereGrid(10.0, *grid_shape).points(33.0).reshape(-1, 3)
    start = time.perf_counter()
    wave, srcs, n_samples = elements(freq, ptd, (lambda w: targets_around(pts, (0.0, 0.0, 33.0), w.k_hat))
                                     if integrand else None)
    t_elements = time.perf_counter() - start
    full = n_samples * len(pts) <= FULL_PAIRS or ref_points <= 0
    idx = np.arange(len(pts)) if full else np.linspace(0, len(pts) - 1, ref_points).astype(int)
    fast = FastRadiator(pts, wave.k, tol=tol, centre=(0, 0, 33.0), force=force)
    direct = Radiator(pts[idx], wave.k)
    t_fast = t_direct = 0.0
    n_src = 0
    for kind, chunks in srcs.items():
        while True:
            start = time.perf_counter()
            chunk = next(chunks, None)
            t_elements += time.perf_counter() - start
            if chunk is None:
                break
            n_src += chunk.shape[1]
            # each piece goes to the reference first (it sums what it is given at once) and then
            # to the fast radiator, which holds it until its batch is summed and then lets it go:
            # the elements are held at most once (at 12 GHz they are 8 GB, four batches)
            start = time.perf_counter()
            for c0 in range(0, chunk.shape[1], REF_CHUNK):  # the radiator copies what it is given
                direct.add_packed(chunk[:, c0:c0 + REF_CHUNK], kind)
            t_direct += time.perf_counter() - start
            start = time.perf_counter()
            fast.add_packed(chunk, kind)
            t_fast += time.perf_counter() - start
            del chunk
    start = time.perf_counter()
    Ef = fast.field()
    t_fast += time.perf_counter() - start
    method = fast.method
    del fast
    start = time.perf_counter()
    Ed = direct.field()
    t_direct = (t_direct + time.perf_counter() - start) * len(pts) / len(idx)
    err = float(np.sqrt(np.mean(np.abs(Ef[idx] - Ed) ** 2) / np.mean(np.abs(Ed) ** 2)))
    return {"freq": freq, "elements": n_src, "points": len(pts), "t_elements": t_elements,
            "t_fast": t_fast, "t_direct": t_direct, "direct_full": full, "err": err,
            "method": method, "peak_gb": peak_rss_gb()}


def peak_rss_gb() -> float:
    """This process's peak resident memory so far (GB; Linux reports kB)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--freqs", type=float, nargs="+", default=[0.1, 0.3, 1.0, 3.0])
    ap.add_argument("--grid", type=int, nargs=2, default=[90, 360])
    ap.add_argument("--tol", type=float, default=1e-6)
    ap.add_argument("--ref-points", type=int, default=400)
    ap.add_argument("--ptd", action="store_true")
    ap.add_argument("--curve", action="store_true")
    ap.add_argument("--integrand", action="store_true")
    args = ap.parse_args()
    run(0.1, (6, 12), args.tol, 50, args.ptd)  # warm-up: compile or load the kernels
    print("| f (GHz) | elements | points | fast (s) | direct (s) | rel. RMS error | peak memory (GB) "
          "| plan |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for f in args.freqs:
        r = run(f, tuple(args.grid), args.tol, args.ref_points, args.ptd, integrand=args.integrand)
        mark = "" if r["direct_full"] else "~"
        plan = "; ".join(f"{k}: {v}" for k, v in r["method"].items())
        print(f"| {f:g} | {r['elements']:,} | {r['points']:,} | {r['t_fast']:.1f} "
              f"| {mark}{r['t_direct']:.1f} | {r['err']:.1e} | {r['peak_gb']:.1f} | {plan} |", flush=True)
    if args.curve:
        print("\n| tol | rel. RMS error | fast (s) | plan |\n| --- | --- | --- | --- |")
        for tol in (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8):
            r = run(args.freqs[0], tuple(args.grid), tol, args.ref_points, args.ptd, force=True,
                    integrand=args.integrand)
            plan = "; ".join(r["method"].values())
            print(f"| {tol:.0e} | {r['err']:.1e} | {r['t_fast']:.1f} | {plan} |", flush=True)


if __name__ == "__main__":
    main()
