"""Running a scan plan on the instruments, one journaled step at a time.

For each step not yet in the journal: announce its index (to a simulator), move both axes to
the step's target and check they got there, wait the settling time, take the plan's number of
readings (more at a reference position), and append the step to the journal (synced to disk)
before the next move. A failure stops the axes and leaves the journal holding every step
completed so far.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from hardware.instruments.motion import MotionController
from hardware.instruments.power_meter import PowerMeter
from hardware.journal import Journal, Record
from hardware.plan import REFERENCE, ScanPlan
from hardware.rig import Rig
from raysim.progress import Progress


@dataclass
class Instruments:
    """The rig's two instruments, opened."""

    meter: PowerMeter
    motion: MotionController

    def close(self) -> None:
        """Close both links (never raises)."""
        self.meter.close()
        self.motion.close()


def prepare(instruments: Instruments, plan: ScanPlan) -> None:
    """Set the meter up for the plan's frequency and the axes for the rig's speed."""
    instruments.meter.setup(plan.frequency_hz)
    rig = plan.rig
    instruments.motion.setup((rig.slider_axis, rig.rotation_axis), rig.speed)


def move_to(motion: MotionController, rig: Rig, slider: float,
            rotation: float) -> tuple[float, float]:
    """Move the rig's axes to (slider, rotation) (rad); return their read-back (rad)."""
    readback = motion.move({rig.slider_axis: slider, rig.rotation_axis: rotation},
                           tolerance=rig.tolerance, timeout_s=rig.move_timeout_s)
    return readback[rig.slider_axis], readback[rig.rotation_axis]


def step_progress(progress: Progress | None, done: int, total: int) -> None:
    """Report ``done`` of ``total`` steps: stage ``step <done> of <total>``, fraction done/total."""
    if progress is not None:
        progress(f"step {done} of {total}", done / total if total else 1.0)


def acquire(plan: ScanPlan, instruments: Instruments, journal: Journal, *,
            progress: Progress | None = None,
            before_step: Callable[[int], None] | None = None) -> None:
    """Take every step of ``plan`` after the journal's last record, journaling each one.

    ``progress(stage, fraction)`` (:mod:`raysim.progress`) is called after each step (see
    :func:`step_progress`); ``before_step(index)`` before it (a simulator keys its noise and
    drift on the index).
    """
    steps = plan.steps()
    start = len(journal.records)
    step_progress(progress, start, len(steps))
    if start >= len(steps):
        return
    prepare(instruments, plan)
    rig = plan.rig
    motion, meter = instruments.motion, instruments.meter
    try:
        for step in steps[start:]:
            if before_step is not None:
                before_step(step.index)
            command = rig.axes(step.theta, step.phi)
            readback = move_to(motion, rig, *command)
            if plan.settle_s > 0:
                time.sleep(plan.settle_s)
            stamp = time.time()
            count = plan.reference_samples if step.kind == REFERENCE else plan.samples_per_point
            power = tuple(meter.read_power() for _ in range(count))
            journal.append(Record(step.index, step.kind, step.i, step.j, command, readback,
                                  power, stamp))
            step_progress(progress, step.index + 1, len(steps))
    except BaseException:
        motion.stop((rig.slider_axis, rig.rotation_axis))
        raise
