"""GO benchmark: the paper scene (90 x 360 cells), mesh + BVH + both traces, on this machine.

Run: ``.venv/bin/python benchmarks/bench_go.py [--repeat 3] [--threads N]``. Kernels are compiled
(or loaded from the cache) by a warm-up trace first, so the figures exclude compilation.
Reports wall time per stage, rays traced, and rays per second per core.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--threads", type=int, default=None, help="CPU threads (default: all cores)")
    parser.add_argument("--scene", default=str(ROOT / "scenes" / "paper_go.toml"))
    args = parser.parse_args()
    if args.threads:
        os.environ["RAYSIM_THREADS"] = str(args.threads)

    from raysim.maps.sphere import SphereGrid
    from raysim.optics import go
    from raysim.optics.runtime import cpu_threads
    from raysim.scene.scene import load_scene
    from raysim.simulate import go_subdivisions
    from raysim.surface.mesh import paraboloid, reflectors_for

    scene = load_scene(args.scene)
    go.trace(paraboloid(20.0, 8.0, 1.0), SphereGrid(3.0, 9, 36))  # compile or load the kernels

    threads = cpu_threads()
    best = None
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        ideal, deformed = reflectors_for(scene)
        t1 = time.perf_counter()
        m = go_subdivisions(scene, ideal)[0]
        a = go.trace(ideal, scene.sphere, scene.source.direction, m)
        t2 = time.perf_counter()
        b = go.trace(deformed, scene.sphere, scene.source.direction, m)
        t3 = time.perf_counter()
        run = (t3 - t0, t1 - t0, t2 - t1, t3 - t2, a.n_rays + b.n_rays, len(ideal.faces))
        best = run if best is None or run[0] < best[0] else best
    total, mesh, t_ideal, t_def, rays, faces = best
    print(f"scene {scene.name}: {scene.sphere.n_theta} x {scene.sphere.n_phi} cells, "
          f"mesh {scene.dish.resolution} m ({faces:,} faces), {threads} CPU thread(s), best of {args.repeat}")
    print(f"  mesh build        {mesh:7.2f} s")
    print(f"  trace ideal       {t_ideal:7.2f} s   (BVH build, rays, reflection, deposition)")
    print(f"  trace deformed    {t_def:7.2f} s")
    print(f"  total             {total:7.2f} s   (target < 20 s on 2 cores)")
    print(f"  rays              {rays:,}   -> {rays / (t_ideal + t_def) / threads:,.0f} rays/s per core")


if __name__ == "__main__":
    main()
