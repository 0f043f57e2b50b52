"""Scan speed through the full PyVISA socket path against the simulated rig.

Prints: the round-trip time of one query, power readings per second (INIT, SYST:ERR?, FETC?,
SYST:ERR?), and whole-scan steps per second (move both axes with TE? checks and MD?/TP? polls,
the readings, a synced journal record per step, the FieldMap written at the end) for 1 and 4
readings a point (references take as many readings as a point here). Motion is
instantaneous (time scale 0), so the figures are the software and protocol overhead a real
rig adds to its own axis and settling times.

    python benchmarks/bench_scan.py [--steps-theta N] [--steps-phi M]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from hardware.config import plan_table as checked_table
from hardware.plan import plan_from_table
from hardware.session import open_instruments, scan
from hardware.sim.rig import SimulatedRig
from hardware.sim.settings import SimSettings
from raysim.maps.fieldmap import fieldmap, save
from raysim.maps.sphere import SphereGrid, ideal_go_intensity

F, D, R = 33.0, 110.0, 10.0


def plan_table(n_theta: int, n_phi: int, samples: int) -> dict:
    return {
        "rig": {"track": {"radius_m": R}, "motion": {"speed_deg_s": 10.0}},
        "reflector": {"focal_length_m": F, "diameter_m": D, "frequency_hz": 3e8},
        "grid": {"theta_max_deg": 80.0, "theta_step_deg": 80.0 / n_theta,
                 "phi_step_deg": 360.0 / n_phi},
        "acquisition": {"samples_per_point": samples, "reference_samples": samples,
                        "reference_every_lines": 4},
        "simulator": {"noise_db": 0.01, "drift_db": 0.05, "time_scale": 0.0},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps-theta", type=int, default=16)
    parser.add_argument("--steps-phi", type=int, default=24)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        grid = SphereGrid(R, 90, 360)
        t, _ = np.meshgrid(grid.theta, grid.phi, indexing="ij")
        ideal = ideal_go_intensity(t, F, R, D)
        field = save(fieldmap(grid, ideal, ideal, focal_length=F, diameter=D, frequency_hz=3e8,
                              method="go", sampling="cell_mean"), folder / "field.nc")

        plan = plan_from_table(checked_table(plan_table(args.steps_theta, args.steps_phi, 1), "bench"))
        with SimulatedRig(plan.rig, SimSettings(time_scale=0.0)) as sim:
            inst = open_instruments(sim.resources, plan.rig)
            inst.meter.setup(3e8)
            n = 500
            start = time.perf_counter()
            for _ in range(n):
                inst.motion.link.query("1TP?")
            rtt = (time.perf_counter() - start) / n
            start = time.perf_counter()
            for _ in range(n):
                inst.meter.read_power()
            reads = n / (time.perf_counter() - start)
            inst.close()
        print(f"query round trip (1TP?):        {rtt * 1e3:7.3f} ms")
        print(f"power readings (4 exchanges):    {reads:7.1f} per s")

        for samples in (1, 4):
            plan = plan_from_table(checked_table(plan_table(args.steps_theta, args.steps_phi, samples),
                                         "bench"))
            steps = len(plan.steps())
            out = folder / f"scan{samples}.nc"
            start = time.perf_counter()
            scan(plan, out, simulate=field, sim=dataclasses.replace(plan.simulator))
            elapsed = time.perf_counter() - start
            cells = plan.grid.n_theta * plan.grid.n_phi
            print(f"scan, {samples} reading(s) a point:   {steps / elapsed:7.1f} steps per s "
                  f"({cells} cells + {steps - cells} references in {elapsed:.2f} s, "
                  f"{math.ceil(elapsed / steps * 1e3)} ms a step)")


if __name__ == "__main__":
    main()
