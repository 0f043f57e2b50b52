"""Scale-out benchmark: the paper's dish at 0.3 GHz, 90 x 360, PO, in blocks on 1 and 2 Dask workers.

Run: ``.venv/bin/python benchmarks/bench_scaleout.py [--workers 1,2] [--n-phi N] [--block-size B]``.

Prints, for each worker count, the wall time, the speed-up over one worker, the figure of merit
(PO pairs per second per worker, radiation time only, and per CPU-second of the block tasks),
the context each worker builds once (reflectors, quadrature, elements) and the overhead per
block: the task's wall time beyond its radiation (the context's build left out), and the
cluster's idle share (worker-seconds not spent in a task, the cluster's start included).
Beside them, the single-process kernel rate on one thread (the radiator alone, 16 384
paper-dish elements x the 32 400 sphere points), in pairs per CPU-second.

Workers are local processes with one thread each (``RAYSIM_THREADS=1``), so on an idle machine
with as many cores as workers the speed-up should be close to the worker count. The load
average before and after each run is printed: on a shared machine the wall times stretch while
the pairs per CPU-second stay, and the ratio of the two tells how loaded it was.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def load() -> str:
    one, five, _ = os.getloadavg()
    return f"load {one:.1f} (1 min), {five:.1f} (5 min) on {os.cpu_count()} cores"


def kernel_rate(n_elements: int = 16384) -> float:
    """Pairs per CPU-second of the radiator on one thread (the single-process kernel rate)."""
    os.environ["RAYSIM_THREADS"] = "1"
    from raysim.maps.sphere import SphereGrid
    from raysim.optics import po
    from raysim.surface.mesh import paraboloid
    from raysim.surface.quadrature import plan

    wave = po.Illumination.plane_wave(0.3e9, (0, 0, -1), (1, 0, 0))
    dish = paraboloid(110.0, 33.0, 5.0)
    src = next(po.po_elements(dish, wave, plan(dish, wave.wavelength, 1.5), chunk=n_elements))
    points = SphereGrid(10.0).points(33.0).reshape(-1, 3)
    po.Radiator(points[:8], wave.k).add_packed(src)  # compile or load
    radiator = po.Radiator(points, wave.k)
    wall, cpu = time.perf_counter(), time.process_time()
    radiator.add_packed(src)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    print(f"single-process kernel, 1 thread: {radiator.pairs:,} pairs in {wall:.2f} s wall, {cpu:.2f} s CPU "
          f"-> {radiator.pairs / wall / 1e6:.1f} M pairs/s, {radiator.pairs / cpu / 1e6:.1f} M pairs per "
          f"CPU-second ({load()})", flush=True)
    return radiator.pairs / cpu


def distributed(workers: int, n_phi: int, block_size: int | None) -> dict:
    from raysim.distributed import simulate
    from raysim.scene.scene import load_scene

    scene = load_scene(ROOT / "scenes" / "paper_po.toml").with_overrides(n_phi=n_phi)
    before = load()
    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        ds = simulate(scene, Path(folder) / "paper_po.nc", "po", workers=workers, block_size=block_size)
        wall = time.perf_counter() - start
    a = ds.attrs
    radiate = a["pairs"] / a["pair_rate"]  # worker-seconds spent radiating
    busy = a["seconds_blocks"]
    row = {"workers": workers, "wall": wall, "pairs": a["pairs"], "blocks": a["blocks"],
           "per_worker": a["pair_rate"], "per_cpu": a["pairs"] / a["seconds_blocks_cpu"],
           "context": a["seconds_context"],
           "block_overhead": (busy - radiate - a["seconds_context_total"]) / a["blocks"],
           "idle": 1.0 - busy / (workers * wall),
           "twice": a["blocks_computed_twice"], "load": f"{before} -> {load()}"}
    print(f"{workers} worker(s): {wall:6.1f} s wall, {a['blocks']} blocks of {a['block_size']}, "
          f"{a['pairs']:,} pairs; {row['per_worker'] / 1e6:.1f} M pairs/s per worker, "
          f"{row['per_cpu'] / 1e6:.1f} M pairs per CPU-second; context {row['context']:.1f} s per worker; "
          f"overhead {row['block_overhead'] * 1e3:.0f} ms per block, idle {100 * row['idle']:.1f} %; "
          f"blocks computed twice {row['twice']} ({row['load']})", flush=True)
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", default="1,2", help="worker counts, comma-separated")
    parser.add_argument("--n-phi", type=int, default=360, help="phi cells (360: the paper's grid)")
    parser.add_argument("--block-size", type=int, default=None, help="points per block (1024)")
    args = parser.parse_args()
    rate = kernel_rate()
    rows = [distributed(int(n), args.n_phi, args.block_size) for n in args.workers.split(",")]
    base = rows[0]
    for row in rows[1:]:
        print(f"speed-up {base['workers']} -> {row['workers']} workers: {base['wall'] / row['wall']:.2f}x "
              f"(wall), per-worker rate {row['per_worker'] / base['per_worker']:.2f} of "
              f"{base['workers']}-worker's")
    for row in rows:
        print(f"{row['workers']} worker(s): {row['per_cpu'] / rate:.2f} of the single-process kernel rate "
              f"per CPU-second ({rate / 1e6:.1f} M)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
