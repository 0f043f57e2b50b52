"""Benchmark of ``raysim dataset`` on the GO paper grid: the cost of one sample and the
throughput of local Dask clusters of 1 and 2 workers.

The dish is the paper's (D = 110 m, F = 33 m, R = 10 m, 90 x 360 one-degree cells, default
0.15 m mesh); each sample is a Zernike spectrum (orders 2..6) plus actuator-scale bumps plus
a gravity-like rim astigmatism, as a training set would hold. Run from the repository root:

    python benchmarks/bench_dataset.py [--samples 16] [--workers 1,2] [--json out/bench.json]

It prints the stages of one sample in this process (drawing, the deformation map, the mesh's
deformed twin, the BVH refit, GO's visibility, surface, reflection and deposition, the store
write; wall time, and the CPU time of the whole sample) and, per cluster, the
wall time, the steady throughput (samples finished per second between the first and the last
completion, so start-up is left out), the speed-up over one worker, and the median wall and
CPU time of a sample's task as the store records them. The load average is printed too: on
a shared machine the figures are only as good as the cores that were free.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

SPEC = """
name = "bench_paper_go"
samples = {samples}
seed = 11
method = "go"
grid_n = 128
validation_fraction = 0.2

[scene]
name = "paper_go_bench"
[scene.dish]
diameter_m = 110.0
focal_length_m = 33.0
resolution_m = 0.15
[scene.source]
frequency_hz = 0.3e9
[scene.sphere]
radius_m = 10.0
n_theta = 90
n_phi = 360

[[errors]]
type = "zernike"
n_min = 2
n_max = 6
rms_um = {{ uniform = [50.0, 300.0] }}

[[errors]]
type = "bumps"
count = {{ integers = [2, 8] }}
sigma_m = {{ uniform = [1.5, 4.0] }}
rms_um = {{ loguniform = [10.0, 60.0] }}

[[errors]]
type = "gravity"
exponent = {{ uniform = [2.5, 4.0] }}
angle_deg = 90.0
rms_um = {{ uniform = [40.0, 150.0] }}
"""


def one_sample(spec, threads: int, folder: Path, repeats: int = 3) -> dict[str, float]:
    """Median stage times (s) of one sample in this process, with ``threads`` per launch.

    Stages: ``draw`` (the random surface and its parameters), ``map`` (delta on the stored
    aperture grid), ``deform`` (the mesh's twin: delta and its slopes at the vertices), ``bvh``
    (refit), ``visibility``, ``surface`` (hits and normals on the smooth surface), ``reflect``,
    ``deposit`` (GO's stages), ``write`` (the sample's arrays into a local Zarr store).
    """
    os.environ["RAYSIM_THREADS"] = str(threads)
    from raysim.dataset import draw_sample
    from raysim.dataset import store as zstore
    from raysim.dataset.engine import go_setup, simulate_sample
    from raysim.dataset.worker import prepare_process

    prepare_process(threads)
    start = time.perf_counter()
    go_setup(spec)
    setup_s = time.perf_counter() - start
    writer = zstore.Writer(zstore.create(str(folder / f"one_t{threads}.zarr"), spec))
    stages: dict[str, list[float]] = {}
    cpu: list[float] = []
    for i in range(repeats + 1):  # the first round warms the caches
        seen: dict[str, float] = {}
        c0 = time.process_time()
        t0 = time.perf_counter()
        draw = draw_sample(spec, i)
        t1 = time.perf_counter()
        deformation_map = spec.grid.evaluate(draw.deformation)
        seen.update(draw=t1 - t0, map=time.perf_counter() - t1)
        values = simulate_sample(spec, draw.deformation, draw.frequency_index,
                                 stages=seen.__setitem__)
        t2 = time.perf_counter()
        writer.params(i, draw.params, spec.frequencies[draw.frequency_index], deformation_map)
        writer.done(i, values, 0.0)
        seen["write"] = time.perf_counter() - t2
        if i:
            cpu.append(time.process_time() - c0)
            for key, value in seen.items():
                stages.setdefault(key, []).append(value)
    out = {key: float(np.median(v)) for key, v in stages.items()}
    out["total"] = sum(out.values())
    out["total_cpu"] = float(np.median(cpu))  # CPU seconds of this process (all its threads)
    out["setup_once"] = setup_s  # ideal mesh, tracer (BVH build), first of the factors
    out["rays"] = float(len(go_setup(spec).ideal.vertices))
    return out


def cluster_run(spec_path: Path, workers: int, threads: int, folder: Path) -> dict[str, float]:
    """Wall time and steady throughput of a local cluster making the whole spec."""
    from raysim.dataset import generate, open_dataset

    store = folder / f"w{workers}_t{threads}.zarr"
    start = time.perf_counter()
    report = generate(spec_path, store, workers=workers, threads=threads)
    wall = time.perf_counter() - start
    ds = open_dataset(store)
    finished = np.sort(ds["finished"].values)
    seconds = ds["seconds"].values
    cpu = ds["cpu_seconds"].values
    span = finished[-1] - finished[0]
    steady = (len(finished) - workers) / span if span > 0 else float("nan")
    return {"workers": workers, "threads": threads, "samples": report.done, "failed": report.failed,
            "wall_s": wall, "steady_samples_per_s": steady,
            "task_seconds_median": float(np.median(seconds)),
            "task_cpu_seconds_median": float(np.median(cpu)),
            "load_average": os.getloadavg()[0]}


def save(results: dict, path: Path | None) -> None:
    """Record the load average at the end and write ``results`` as JSON to ``path`` (if any)."""
    results["load_average_end"] = os.getloadavg()
    if path:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(results, indent=2))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--workers", default="1,2", help="comma-separated local worker counts")
    parser.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = parser.parse_args()
    from raysim.dataset import load_spec

    folder = Path(tempfile.mkdtemp(prefix="bench_dataset_"))
    try:
        spec_path = folder / "bench.toml"
        spec_path.write_text(SPEC.format(samples=args.samples))
        spec = load_spec(spec_path)
        print(f"cores usable: {len(os.sched_getaffinity(0))}, load average {os.getloadavg()}")
        results: dict[str, object] = {"one_sample": {}, "clusters": []}
        for threads in (1, 2):
            cost = one_sample(spec, threads, folder)
            results["one_sample"][f"threads_{threads}"] = cost
            print(f"one sample, {threads} thread(s) per launch: " + ", ".join(
                f"{k} {v:.3f} s" if k != "rays" else f"{int(v):,} rays" for k, v in cost.items()))
        base = None
        for workers in (int(w) for w in args.workers.split(",")):
            row = cluster_run(spec_path, workers, 1, folder)
            base = base or row["steady_samples_per_s"]
            row["speedup"] = row["steady_samples_per_s"] / base
            results["clusters"].append(row)
            print(f"{workers} worker(s) x 1 thread: {row['samples']} samples in {row['wall_s']:.1f} s "
                  f"wall, steady {row['steady_samples_per_s']:.3f} samples/s "
                  f"(x{row['speedup']:.2f}), median task {row['task_seconds_median']:.2f} s wall, "
                  f"{row['task_cpu_seconds_median']:.2f} s CPU; load {row['load_average']:.1f}")
        row = cluster_run(spec_path, 1, 2, folder)
        results["clusters"].append(row)
        print(f"1 worker x 2 threads: {row['samples']} samples in {row['wall_s']:.1f} s wall, steady "
              f"{row['steady_samples_per_s']:.3f} samples/s, "
              f"median task {row['task_seconds_median']:.2f} s wall, "
              f"{row['task_cpu_seconds_median']:.2f} s CPU; load {row['load_average']:.1f}")
        save(results, args.json)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
