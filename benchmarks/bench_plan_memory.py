"""Memory of the fast radiator's planning on the paper's dish, per PO element, phase by phase.

Run: ``python benchmarks/bench_plan_memory.py [--freqs 3 6 12] [--grid 90 360]``.

The part of a wave-optics ``simulate`` whose memory grows with the elements, without the walk
(the sum itself, whose grids are held a chunk at a time, ``GRID_BYTES``): for each frequency
in a fresh process, the PO elements of ``scenes/paper_po.toml``'s ideal reflector as the
quadrature makes them, the tree planned on them (``plan_for``) and the elements gathered into
its leaf order; then the deformed reflector's elements, the check that the ideal tree serves
them (``holds``) and their leaf order. A thread reads the resident set every 20 ms; each
phase's figure is its peak above what the process held before the elements, in bytes per
element (the elements themselves are 72), and the process's peak in GB.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def resident() -> float:
    """This process's resident set (bytes)."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * 4096.0


class Peaks:
    """Peak resident set per named phase, read by a thread every 20 ms."""

    def __init__(self) -> None:
        self.phase = "start"
        self.peaks: dict[str, float] = {}
        threading.Thread(target=self._watch, daemon=True).start()

    def _watch(self) -> None:
        while True:
            self.note()
            time.sleep(0.02)

    def note(self) -> None:
        now = resident()
        self.peaks[self.phase] = max(self.peaks.get(self.phase, 0.0), now)

    def enter(self, phase: str) -> None:
        self.note()
        self.phase = phase
        self.note()


def one(freq_ghz: float, grid: tuple[int, int]) -> dict:
    import raysim
    from raysim.optics import po
    from raysim.optics.bvh import ReflectorBVH
    from raysim.optics.fast import multilevel
    from raysim.optics.fast.chart import domain_of
    from raysim.optics.fast.radiator import DEFAULT_TOL, plan_for
    from raysim.simulate import _wave
    from raysim.surface.mesh import reflectors_for
    from raysim.surface.quadrature import plan

    scene = raysim.load_scene(ROOT / "scenes" / "paper_po.toml").with_overrides(freq_ghz * 1e9, *grid)
    ideal, deformed = reflectors_for(scene)
    wave = _wave(scene)
    domain = domain_of(scene.sphere.points(ideal.F).reshape(-1, 3), (0.0, 0.0, float(ideal.F)))
    peaks = Peaks()
    out: dict = {"freq": freq_ghz}

    def elements(reflector):
        quad = plan(reflector, wave.wavelength, po.DEFAULT_SAMPLES_PER_WAVELENGTH)
        bvh = ReflectorBVH.build(reflector, "cpu")
        return [chunk.numpy() for chunk in po.po_elements(reflector, wave, quad, bvh=bvh)]

    base = resident()
    peaks.enter("ideal: elements")
    pieces = elements(ideal)
    n = sum(piece.shape[1] for piece in pieces)
    peaks.enter("ideal: plan")
    the_plan = plan_for(pieces, domain, wave.k, DEFAULT_TOL)
    assert the_plan is not None
    peaks.enter("ideal: leaf order")
    ordered = multilevel.leaf_ordered(pieces, the_plan)
    peaks.enter("ideal: done")
    del ordered, pieces
    peaks.enter("deformed: elements")
    pieces = elements(deformed)
    peaks.enter("deformed: holds")
    out["holds"] = multilevel.holds(the_plan, pieces, domain, wave.k)
    peaks.enter("deformed: leaf order")
    ordered = multilevel.leaf_ordered(pieces, the_plan)
    peaks.enter("end")
    assert ordered.shape[1] == n
    out.update(n=n, peak_gb=max(peaks.peaks.values()) / 1e9,
               phases={name: (peak - base) / n for name, peak in peaks.peaks.items() if name != "start"})
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--freqs", type=float, nargs="+", default=[3.0, 6.0])
    ap.add_argument("--grid", type=int, nargs=2, default=[90, 360])
    ap.add_argument("--one", type=float, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one is not None:
        print(json.dumps(one(args.one, tuple(args.grid))))
        return
    names = ["ideal: elements", "ideal: plan", "ideal: leaf order", "deformed: holds", "deformed: leaf order"]
    print("| f (GHz) | PO elements | " + " | ".join(names) + " | peak (GB) | ideal tree holds |")
    print("| --- | --- |" + " --- |" * (len(names) + 2))
    for f in args.freqs:
        cmd = [sys.executable, __file__, "--one", str(f), "--grid", *map(str, args.grid)]
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            print(f"| {f:g} | failed: {done.stderr.strip().splitlines()[-1:]} |", flush=True)
            continue
        r = json.loads(done.stdout.strip().splitlines()[-1])
        cells = " | ".join(f"{r['phases'].get(name, float('nan')):.0f}" for name in names)
        print(f"| {f:g} | {r['n']:,} | {cells} | {r['peak_gb']:.1f} | {r['holds']} |", flush=True)


if __name__ == "__main__":
    main()
