"""``raysim check`` on the paper's dish (D = 110 m, F = 33 m, R = 10 m, Eq. 8) at 0.3, 1 and 3 GHz:
each step's time (GO, the wave engine, the three inversions) and the check's figures.

The engine rule picks PO + PTD at all three (its samples fit the memory up to 35 GHz on 25 GB);
the wave-aware refinement uses the data's own model (a PO + PTD run per iteration: most of the
time). Two cores by default (``RAYSIM_THREADS`` caps the threads).

Run: ``nice -n 10 .venv/bin/python benchmarks/bench_check.py [--sphere 90x360] [--grid 256]
[--refine-model auto] [-o out/bench_check]``; the page and check.nc land in the output folder.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

FREQUENCIES_HZ = (0.3e9, 1e9, 3e9)
STEPS = ("go", "wave", "invert_go_data", "invert_go_model", "invert_wave_model")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sphere", default="90x360", help="probe-sphere cells NTHETAxNPHI")
    parser.add_argument("--grid", type=int, default=256, help="aperture grid of the inversions")
    parser.add_argument("--refine-model", default="auto", help="wave-aware refinement model")
    parser.add_argument("-o", "--output", default=str(ROOT / "out" / "bench_check"))
    args = parser.parse_args()
    os.environ.setdefault("RAYSIM_THREADS", "2")

    from raysim.pipeline.check import summary_rows, verdict_lines, write_check
    from raysim.pipeline.check_inputs import parse_grid

    load = os.getloadavg()[0]
    start = time.perf_counter()
    page, ds = write_check("paper_go", args.output, frequencies=list(FREQUENCIES_HZ),
                           grid=parse_grid(args.sphere), N=args.grid, refine_model=args.refine_model,
                           progress=lambda stage, f: print(f"{time.strftime('%H:%M:%S')} {100 * f:5.1f} % "
                                                           f"{stage}", flush=True) if f == 0 or
                           stage.endswith("done") else None)
    total = time.perf_counter() - start
    print(f"\npaper dish, sphere {args.sphere}, N = {args.grid}, {os.environ['RAYSIM_THREADS']} threads, "
          f"load average at the start {load:.1f}, at the end {os.getloadavg()[0]:.1f}")
    print(f"{'f GHz':>6s} {'engine':>8s} " + " ".join(f"{s:>18s}" for s in STEPS))
    for i, f in enumerate(ds["frequency"].values):
        times = " ".join(f"{float(ds[f'seconds_{s}'].values[i]):17.1f}s" for s in STEPS)
        print(f"{f / 1e9:6g} {ds['wave_method'].values[i]!s:>8s} {times}")
    print(f"total wall time {total:.0f} s (with the page)\n")
    for row in summary_rows(ds):
        print(" | ".join(row))
    for line in verdict_lines(ds):
        print(line)
    print(page)


if __name__ == "__main__":
    main()
