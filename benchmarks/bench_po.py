"""PO benchmark: pair rate of the radiation kernel and the paper case (0.3 GHz, 90 x 360) wall time.

Run: ``.venv/bin/python benchmarks/bench_po.py [--threads N] [--skip-paper] [--checks]``.
Kernels are compiled (or loaded from the cache) by a warm-up first, so the figures exclude
compilation. A pair is one current element times one field point. Besides wall time the
script prints the process's CPU time: on a shared machine (other jobs on the same cores) the
wall time stretches while CPU time per pair stays, and CPU-seconds / threads is the wall time
the same work takes on idle cores. ``--checks`` adds the accuracy figures of issue 5 (paper
case refined on a 90 x 36 grid, tapered PO against GO at 3 GHz on the paper's dish).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


class Clock:
    """Wall and process CPU time of a block."""

    def __enter__(self):
        self.wall, self.cpu = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall = time.perf_counter() - self.wall
        self.cpu = time.process_time() - self.cpu


def kernel_rate(threads: int, n_elements: int = 16384) -> None:
    """Radiator alone: 32 400 sphere points x ``n_elements`` PO elements of the paper dish."""
    from raysim.maps.sphere import SphereGrid
    from raysim.optics import po
    from raysim.surface.mesh import paraboloid
    from raysim.surface.quadrature import plan

    wave = po.Illumination.plane_wave(0.3e9, (0, 0, -1), (1, 0, 0))
    dish = paraboloid(110.0, 33.0, 5.0)
    src = next(po.po_elements(dish, wave, plan(dish, wave.wavelength, 1.5), chunk=n_elements))
    points = SphereGrid(10.0).points(33.0).reshape(-1, 3)
    po.Radiator(points[:8], wave.k).add_packed(src)  # warm-up: compile or load
    radiator = po.Radiator(points, wave.k)
    with Clock() as c:
        radiator.add_packed(src)
    pairs = radiator.pairs
    print(f"radiation kernel: {len(points):,} points x {src.shape[1]:,} elements = {pairs:,} pairs, "
          f"{threads} thread(s)")
    print(f"  wall {c.wall:6.2f} s  -> {pairs / c.wall / 1e6:6.1f} M pairs/s")
    print(f"  CPU  {c.cpu:6.2f} s  -> {pairs / c.cpu / 1e6:6.1f} M pairs per CPU-second, "
          f"{threads * pairs / c.cpu / 1e6:6.1f} M pairs/s on {threads} idle core(s)")


def paper_case(threads: int, spw: float | None) -> None:
    from raysim.scene.scene import load_scene
    from raysim.simulate import simulate

    scene = load_scene(ROOT / "scenes" / "paper_po.toml")
    with Clock() as c:
        ds = simulate(scene, method="po", samples_per_wavelength=spw)
    a = ds.attrs
    print(f"paper case {scene.name}: {scene.sphere.n_theta} x {scene.sphere.n_phi} points, "
          f"{a['samples']:,} samples per reflector (spw {a['samples_per_wavelength']:g}), "
          f"{a['pairs']:,} pairs, {threads} thread(s)")
    print(f"  wall {c.wall:7.1f} s  (target < 300 s on 2 cores; {a['pairs'] / c.wall / 1e6:.1f} M pairs/s)")
    print(f"  CPU  {c.cpu:7.1f} s  -> {c.cpu / threads:7.1f} s on {threads} idle core(s), "
          f"{threads * a['pairs'] / c.cpu / 1e6:.1f} M pairs/s")
    FA = ds["intensity_ideal"].values / ds["intensity"].values - 1.0
    print(f"  FA rms {np.sqrt(np.mean(FA**2)):.3e}, max |FA| {np.abs(FA).max():.3e}")


def refinement_check() -> None:
    """Paper case, every theta and every tenth phi: default sampling against spw 2.5."""
    from dataclasses import replace

    from raysim.scene.scene import load_scene
    from raysim.simulate import simulate

    scene = load_scene(ROOT / "scenes" / "paper_po.toml").with_overrides(None, 90, 36)
    out = {}
    for spw in (None, 2.5):
        ds = simulate(replace(scene), method="po", samples_per_wavelength=spw)
        out[spw] = (ds["intensity_ideal"].values, ds["intensity"].values, ds.attrs["samples"])
    (i0, i1, n0), (j0, j1, n1) = out[None], out[2.5]
    FA, FA_fine = i0 / i1 - 1, j0 / j1 - 1
    signal = np.sqrt(np.mean(FA_fine**2))
    print(f"paper case refinement (90 x 36 points, {n0:,} vs {n1:,} samples): FA rms {signal:.3e}")
    print(f"  max |dFA| {np.abs(FA - FA_fine).max():.2e} = {np.abs(FA - FA_fine).max() / signal:.1e} "
          f"of the signal; max |dI/I| ideal {np.abs(i0 / j0 - 1).max():.2e}, "
          f"deformed {np.abs(i1 / j1 - 1).max():.2e}")


def go_check() -> None:
    """Paper's dish at 3 GHz, current tapered smoothly to 0 at the rim, theta <= 40 deg."""
    from raysim.maps.sphere import SphereGrid, ideal_go_intensity
    from raysim.optics import po
    from raysim.surface.mesh import paraboloid

    def f(u):
        return np.where(u > 0, np.exp(-1.0 / np.maximum(u, 1e-300)), 0.0)

    def taper(x, y, r0=35.0, r1=55.0):
        t = np.clip((r1 - np.hypot(x, y)) / (r1 - r0), 0.0, 1.0)
        return f(t) / (f(t) + f(1.0 - t))

    grid = SphereGrid(10.0, 40, 12, theta_max=np.radians(40.0))
    wave = po.Illumination.plane_wave(3e9, (0, 0, -1), (1, 0, 0))
    with Clock() as c:
        result = po.sphere_field(paraboloid(110.0, 33.0, 5.0), grid, wave, taper=taper)
    intensity = np.sum(np.abs(result.E) ** 2, axis=-1)
    rel = intensity / ideal_go_intensity(grid.theta, 33.0, 10.0)[:, None] - 1.0
    print(f"tapered PO vs GO at 3 GHz ({grid.n_theta} x {grid.n_phi} points, theta 0.5..39.5 deg, "
          f"{result.n_samples:,} samples, {c.wall:.0f} s): max |I/GO - 1| {np.abs(rel).max():.2e}, "
          f"rms {np.sqrt(np.mean(rel**2)):.2e}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=None, help="CPU threads (default: all cores)")
    parser.add_argument("--spw", type=float, default=None, help="samples per wavelength (default: PO's)")
    parser.add_argument("--skip-paper", action="store_true", help="kernel rate only")
    parser.add_argument("--checks", action="store_true", help="also the accuracy checks (slow)")
    args = parser.parse_args()
    if args.threads:
        os.environ["RAYSIM_THREADS"] = str(args.threads)
    from raysim.optics.runtime import cpu_threads

    threads = cpu_threads()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())} "
          f"(over {os.cpu_count()} cores: more means other jobs share them)")
    kernel_rate(threads)
    if not args.skip_paper:
        paper_case(threads, args.spw)
    if args.checks:
        refinement_check()
        go_check()
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
