"""What a wave-optics field costs on the paper's dish, from 0.1 GHz up: GO, PO + PTD with the fast
radiator, and the direct sum (issue 31's table).

Run: ``python benchmarks/bench_wave_cost.py [--freqs 0.1 0.3 1 3] [--grid 90 360]
[--method po+ptd] [--direct-upto 0.1] [--rate-points 400]``.

Each frequency runs in a fresh process (so its peak memory is its own): ``raysim.simulate`` of
``scenes/paper_go.toml`` (GO, deformed and ideal) and of ``scenes/paper_po.toml`` with
``--method`` (default PO + PTD; ideal and deformed reflectors, Eq. 8), the fast radiator at its
default tolerance. Beside them, the direct sum's time: measured (``radiator="direct"``) up to
``--direct-upto`` GHz, beyond that the run's element-point pairs (its ``pairs`` and
``pairs_edges``) divided by the direct sum's rate, measured once at the start on
``--rate-points`` points (marked ``~``). Peak memory is the process's maximum resident set.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def one(freq_ghz: float, grid: tuple[int, int], method: str, direct: bool) -> dict:
    """The figures of one frequency, in this process."""
    import raysim

    out: dict = {"freq": freq_ghz}
    go = raysim.load_scene(ROOT / "scenes" / "paper_go.toml").with_overrides(freq_ghz * 1e9, *grid)
    start = time.perf_counter()
    raysim.simulate(go, method="go")
    out["go_s"] = time.perf_counter() - start
    wave = raysim.load_scene(ROOT / "scenes" / "paper_po.toml").with_overrides(freq_ghz * 1e9, *grid)
    start = time.perf_counter()
    fm = raysim.simulate(wave, method=method)
    out["fast_s"] = time.perf_counter() - start
    out["pairs"] = float(fm.attrs.get("pairs", 0)) + float(fm.attrs.get("pairs_edges", 0))
    out["samples"] = int(fm.attrs.get("samples", 0))
    out["ran"] = str(fm.attrs.get("radiator_ran", ""))
    out["rss_gb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    if direct:
        start = time.perf_counter()
        ref = raysim.simulate(wave, method=method, radiator="direct")
        out["direct_s"] = time.perf_counter() - start
        a, b = fm["intensity"].values, ref["intensity"].values
        out["err"] = float(((a - b) ** 2).sum() ** 0.5 / (b**2).sum() ** 0.5)
    return out


def direct_rate(points: int) -> float:
    """Element-point pairs per second of the direct sum (PO elements of the paper's dish at
    0.3 GHz on ``points`` points of the grid)."""
    import numpy as np

    from raysim.maps.sphere import SphereGrid
    from raysim.optics import po
    from raysim.optics.radiator import Radiator
    from raysim.surface.mesh import paraboloid
    from raysim.surface.quadrature import plan

    wave = po.Illumination.plane_wave(0.3e9, (0, 0, -1), (1, 0, 0))
    dish = paraboloid(110.0, 33.0, 5.0)
    quad = plan(dish, wave.wavelength, po.DEFAULT_SAMPLES_PER_WAVELENGTH)
    src = np.concatenate([s.numpy() for s in po.po_elements(dish, wave, quad)], axis=1)
    pts = SphereGrid(10.0, 90, 360).points(33.0).reshape(-1, 3)
    pts = pts[np.linspace(0, len(pts) - 1, points).astype(int)]
    Radiator(pts[:8], wave.k).add_packed(src[:, :64], "electric")  # compile or load the kernels
    start = time.perf_counter()
    r = Radiator(pts, wave.k)
    r.add_packed(src, "electric")
    r.field()
    return src.shape[1] * len(pts) / (time.perf_counter() - start)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--freqs", type=float, nargs="+", default=[0.1, 0.3, 1.0, 3.0])
    ap.add_argument("--grid", type=int, nargs=2, default=[90, 360])
    ap.add_argument("--method", default="po+ptd")
    ap.add_argument("--direct-upto", type=float, default=0.1)
    ap.add_argument("--rate-points", type=int, default=400)
    ap.add_argument("--one", type=float, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one is not None:
        print(json.dumps(one(args.one, tuple(args.grid), args.method, args.one <= args.direct_upto)))
        return
    rate = direct_rate(args.rate_points)
    print(f"direct sum: {rate / 1e6:.0f} M pairs/s\n")
    print("| f (GHz) | PO samples | GO (s) | fast (s) | direct (s) | fast / direct | peak memory (GB) "
          "| rel. RMS of I vs direct | sums |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for f in args.freqs:
        cmd = [sys.executable, __file__, "--one", str(f), "--grid", *map(str, args.grid), "--method",
               args.method, "--direct-upto", str(args.direct_upto)]
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            print(f"| {f:g} | failed: {done.stderr.strip().splitlines()[-1:]} |", flush=True)
            continue
        r = json.loads(done.stdout.strip().splitlines()[-1])
        measured = "direct_s" in r
        t_direct = r["direct_s"] if measured else r["pairs"] / rate
        err = f"{r['err']:.1e}" if measured else ""
        print(f"| {f:g} | {r['samples']:,} | {r['go_s']:.1f} | {r['fast_s']:.1f} "
              f"| {'' if measured else '~'}{t_direct:.0f} | {r['fast_s'] / t_direct:.3f} | {r['rss_gb']:.1f} "
              f"| {err} | {r['ran']} |", flush=True)


if __name__ == "__main__":
    main()
