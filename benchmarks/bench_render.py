"""Benchmark: a 90 x 360 FieldMap to PNG, each kind, in a fresh process after import.

Target (issue 7): under 5 s per picture after import. The first picture of a process pays for
the EGL context and VTK's shaders, so it is timed on its own ("first"); later pictures reuse
nothing but the warm caches ("again"). Wall and CPU seconds are both printed: on a shared
machine the wall time includes waiting for the CPU.

    python benchmarks/bench_render.py [FIELD.nc] [--size WxH] [--repeat N]

Without a file the map is the paper's GO case (Eq. 8 on the 90 x 360 grid) traced by the
project's GO engine (:func:`raysim.pipeline.paper.paper_fieldmap`, a few seconds).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 5.0


def main(argv: list[str] | None = None) -> dict[str, dict[str, float]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("field", nargs="?", help="FieldMap NetCDF (default: the paper's GO case)")
    parser.add_argument("--size", default=None, help="picture size WxH (default: each kind's default)")
    parser.add_argument("--repeat", type=int, default=2, help="pictures per kind after the first")
    args = parser.parse_args(argv)

    start = time.perf_counter()
    from raysim.render import render
    from raysim.render.backend import pyvista

    pyvista()  # import pyvista and VTK here: the target is for rendering after import
    if args.field:
        from raysim.render.data import open_map

        _, ds = open_map(args.field)
    else:
        from raysim.pipeline.paper import paper_fieldmap

        ds = paper_fieldmap()
    print(f"import and map: {time.perf_counter() - start:.2f} s; map {ds.sizes['theta']} x "
          f"{ds.sizes['phi']}; {os.cpu_count()} CPUs; load average {os.getloadavg()[0]:.1f}")
    results: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as folder:
        for kind in ("3d", "map", "cut"):
            times = []
            for _ in range(1 + args.repeat):
                wall, cpu = time.perf_counter(), time.process_time()
                render(ds, Path(folder) / f"{kind}.png", kind=kind, size=args.size)
                times.append((time.perf_counter() - wall, time.process_time() - cpu))
            first, again = times[0], times[1:]
            results[kind] = {"first_wall": first[0], "first_cpu": first[1],
                             "again_wall": min(t[0] for t in again) if again else float("nan"),
                             "again_cpu": min(t[1] for t in again) if again else float("nan")}
            verdict = "ok" if first[0] < TARGET_S else f"OVER the {TARGET_S:g} s target"
            again_wall, again_cpu = results[kind]["again_wall"], results[kind]["again_cpu"]
            print(f"{kind:>4}: first {first[0]:5.2f} s wall ({first[1]:5.2f} s CPU), again "
                  f"{again_wall:5.2f} s wall ({again_cpu:5.2f} s CPU)  {verdict}")
    return results


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    main()
