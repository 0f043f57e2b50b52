"""GPU benchmark: PO pair rate on CUDA and the paper's dish at 3 GHz, 90 x 360, PO + PTD.

Run: ``.venv/bin/python benchmarks/bench_gpu.py [--budget S] [--out FILE]`` (``scripts/device-check``
runs it after the GPU tests). A pair is one current element times one field point. Kernels are
compiled first (timed apart); each figure is then one timed run. The 3 GHz case runs with the
direct sum, skipped (saying so) when the pair rate measured predicts it would not fit in what
is left of the budget, then with the fast (multilevel) radiator when at least
:data:`FAST_SECONDS` are left: its leaf and re-phasing kernels run on the GPU but its FFTs on
the host, and its choice against the direct sum is costed for two CPU cores, so the two times
side by side say whether that choice holds on a GPU. Figures go to stdout and, one line at a
time as a short Markdown list, to ``--out`` (a run cut short keeps what it measured).
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
FAST_SECONDS = 120.0  # the fast radiator's 3 GHz run is tried with at least this much budget left
sys.path.insert(0, str(ROOT))


def gpu_name() -> str:
    try:
        run = subprocess.run(["nvidia-smi", "--query-gpu=name,memory.total,driver_version",
                              "--format=csv,noheader"], capture_output=True, text=True, timeout=20)
        lines = run.stdout.strip().splitlines() if run.returncode == 0 else []
        return lines[0] if lines else "unknown GPU"
    except (OSError, subprocess.TimeoutExpired):
        return "unknown GPU (no nvidia-smi)"


def paper_elements(frequency_hz: float, n_elements: int, device: str):
    """The first ``n_elements`` PO elements of the paper dish at ``frequency_hz`` on ``device``."""
    from raysim.optics import po
    from raysim.surface.mesh import paraboloid
    from raysim.surface.quadrature import plan

    wave = po.Illumination.plane_wave(frequency_hz, (0, 0, -1), (1, 0, 0))
    dish = paraboloid(110.0, 33.0, 5.0)
    return wave, next(po.po_elements(dish, wave, plan(dish, wave.wavelength, 1.5), device, chunk=n_elements))


def pair_rate(device: str, n_points: int, n_elements: int) -> tuple[float, float]:
    """(pairs/s, seconds) of the radiator: ``n_points`` paper-sphere points x ``n_elements``."""
    from raysim.maps.sphere import SphereGrid
    from raysim.optics.radiator import Radiator

    wave, src = paper_elements(3e9, n_elements, device)
    grid = SphereGrid(10.0)
    points = grid.points(33.0).reshape(-1, 3)
    points = np.resize(points, (n_points, 3)) if n_points != len(points) else points
    Radiator(points[:64], wave.k, device).add_packed(src)  # warm-up
    radiator = Radiator(points, wave.k, device)
    start = time.perf_counter()
    radiator.add_packed(src)
    radiator.field()  # waits for the device
    seconds = time.perf_counter() - start
    return radiator.pairs / seconds, seconds


def paper_3ghz(device: str, radiator: str) -> dict:
    from raysim.scene.scene import load_scene
    from raysim.simulate import simulate

    scene = load_scene(ROOT / "scenes" / "paper_po.toml").with_overrides(frequency_hz=3e9)
    start = time.perf_counter()
    ds = simulate(scene, method="po+ptd", device=device, radiator=radiator)
    a = ds.attrs
    FA = ds["intensity_ideal"].values / ds["intensity"].values - 1.0
    return {"seconds": time.perf_counter() - start, "pairs": a["pairs"], "pair_rate": a["pair_rate"],
            "samples": a["samples"], "edge_points": a["edge_points"], "FA": FA,
            "fa_rms": float(np.sqrt(np.mean(FA**2)))}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=float, default=240.0, help="seconds for the whole benchmark")
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "device-figures.md")
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--scale", type=float, default=1.0,
                        help="fraction of the rate runs' elements (a dry run on the CPU: 0.001)")
    args = parser.parse_args()
    start = time.perf_counter()
    from raysim.distributed.process import load_kernels
    from raysim.optics import runtime

    wp = runtime.init()
    if args.device.startswith("cuda") and not wp.is_cuda_available():
        print("bench_gpu: no CUDA GPU here, skipped")
        return 0
    args.out.parent.mkdir(parents=True, exist_ok=True)

    def record(line: str) -> None:
        """One figure to stdout and, at once, to the figures file."""
        print(line, flush=True)
        with args.out.open("a") as fh:
            fh.write(line + "\n")

    record(f"- device: {gpu_name()}; warp {wp.__version__}, Python {platform.python_version()}")
    t = time.perf_counter()
    load_kernels(args.device)
    record(f"- kernels compiled or loaded on {args.device}: {time.perf_counter() - t:.1f} s")
    rates = {}
    for n_points, full in ((32_400, 1 << 20), (4 * 32_400, 1 << 19)):
        n_elements = max(256, int(full * args.scale))
        rate, seconds = pair_rate(args.device, n_points, n_elements)
        rates[n_points] = rate
        record(f"- PO pair rate, float64: {rate / 1e9:.2f} G pairs/s ({n_points:,} points x "
               f"{n_elements:,} elements in {seconds:.2f} s)")
    # the paper dish at 3 GHz: about 2 x 7.5e6 elements x 32 400 points, plus the rim
    predicted = 2 * 7.54e6 * 32_400 / rates[32_400] * 1.3
    left = args.budget - (time.perf_counter() - start)
    direct = None
    if predicted < left:
        direct = paper_3ghz(args.device, "direct")
        record(f"- paper dish, 3 GHz, 90 x 360, PO + PTD (rim) on {args.device}, direct sum: "
               f"{direct['seconds']:.1f} s ({direct['samples']:,} samples per reflector, "
               f"{direct['edge_points']:,} edge points, {direct['pairs']:.3g} PO pairs at "
               f"{direct['pair_rate'] / 1e9:.2f} G/s; FA rms {direct['fa_rms']:.3e})")
    else:
        record(f"- paper dish, 3 GHz, 90 x 360, PO + PTD, direct sum: skipped (predicted "
               f"{predicted:.0f} s from the pair rate, {max(left, 0.0):.0f} s of the budget left)")
    left = args.budget - (time.perf_counter() - start)
    if left >= FAST_SECONDS:
        fast = paper_3ghz(args.device, "fast")
        agree = ""
        if direct is not None:
            err = np.sqrt(np.mean((fast["FA"] - direct["FA"]) ** 2) / np.mean(direct["FA"] ** 2))
            agree = f"; FA against the direct sum's {err:.1e} relative RMS"
        record(f"- paper dish, 3 GHz, 90 x 360, PO + PTD (rim) on {args.device}, fast radiator: "
               f"{fast['seconds']:.1f} s{agree}")
    else:
        record(f"- paper dish, 3 GHz, fast radiator: skipped ({max(left, 0.0):.0f} s of the budget left, "
               f"{FAST_SECONDS:.0f} s wanted)")
    print(f"figures appended to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
