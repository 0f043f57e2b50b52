"""The rig's top-level operations: ``scan`` (plan -> journal -> FieldMap) and ``park``.

Both run against the real instruments (VISA resource names by role: ``meter``, ``motion``) or
against a simulated rig started on loopback sockets for the duration of the call. The FieldMap
is always assembled from the journal as it stands on disk and written atomically, so an
interrupted and resumed scan gives the same file as an uninterrupted one.
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyvisa
import xarray as xr

from hardware.acquire import Instruments, acquire, move_to, step_progress
from hardware.assemble import build_fieldmap
from hardware.errors import JournalError, PlanError
from hardware.instruments.motion import MotionController
from hardware.instruments.power_meter import PowerMeter
from hardware.interp import SphereField
from hardware.journal import Journal, Record, not_being_written, read_journal, read_journal_sessions
from hardware.plan import REFERENCE, ScanPlan, w_to_dbm
from hardware.rig import Rig
from hardware.sim.rig import Faults, SimulatedRig
from hardware.sim.settings import SimSettings
from raysim.files import check_output
from raysim.maps import fieldmap as fieldmaps
from raysim.maps.probe import probe_of
from raysim.maps.sphere import SphereGrid
from raysim.progress import Progress

ROLES = ("meter", "motion")


@dataclass(frozen=True)
class ScanResult:
    """What :func:`scan` did: the FieldMap, its path, the journal, steps taken this call."""

    fieldmap: xr.Dataset
    output: Path
    journal: Path
    steps_total: int
    steps_taken: int


def journal_path(output: str | os.PathLike[str]) -> Path:
    """The journal next to a scan's output: ``SCAN.nc`` -> ``SCAN.nc.journal``."""
    output = Path(output)
    return output.with_name(output.name + ".journal")


def parse_resources(items: list[str] | None) -> dict[str, str]:
    """``ROLE=VISA`` strings (roles ``meter``, ``motion``) to a dict; one-line errors."""
    out: dict[str, str] = {}
    for item in items or []:
        role, sep, resource = item.partition("=")
        if not sep or role.strip() not in ROLES or not resource.strip():
            raise PlanError(f"--resource '{item}': write ROLE=VISA with ROLE one of "
                            f"{', '.join(ROLES)}, e.g. meter=TCPIP::10.0.0.5::5025::SOCKET")
        out[role.strip()] = resource.strip()
    return out


def scan(plan: ScanPlan, output: str | os.PathLike[str], *,
         resources: Mapping[str, str] | None = None, simulate: str | os.PathLike[str] | None = None,
         sim: SimSettings | None = None, faults: Faults = Faults(), resume: bool = False,
         journal: str | os.PathLike[str] | None = None, progress: Progress | None = None,
         rm: pyvisa.ResourceManager | None = None) -> ScanResult:
    """Run ``plan`` and write the measured FieldMap to ``output`` (NetCDF, atomically).

    Parameters
    ----------
    plan : the scan plan (its rig gives R and the default instrument addresses).
    output : the FieldMap file; the journal defaults to ``output`` + ``.journal``.
    resources : VISA addresses by role (``meter``, ``motion``), over the rig file's.
    simulate : a FieldMap to scan with a simulated rig instead of instruments.
    sim : simulator settings (default: the plan's ``[simulator]`` table).
    faults : faults the simulated instruments inject (tests).
    resume : continue the journal after its last complete step; without it an existing
        journal with records is an error, with it a missing one (or one holding no step).
    progress : ``progress(stage, fraction)`` after each step (:func:`hardware.acquire.step_progress`).
    rm : PyVISA resource manager (default: pyvisa-py).
    """
    output = Path(output)
    jpath = Path(journal) if journal is not None else journal_path(output)
    check_output(output, [("journal", jpath), ("FieldMap the simulated rig scans", simulate)],
                 PlanError)
    check_output(jpath, [("FieldMap the simulated rig scans", simulate)], PlanError)
    if resources and simulate is not None:
        raise PlanError("give either --resource or --simulate, not both")
    plan.check_tolerance()  # before any journal, instrument or motion
    if resume and not journal_records(jpath):
        # starting afresh instead re-scanned everything (hours on a real rig) and left the
        # real journal, wherever it was, orphaned
        raise JournalError(f"no journal to resume at {jpath}; run without --resume to start the scan")
    settings = sim if sim is not None else plan.simulator
    steps = plan.steps()
    with _instrument_addresses(plan, resources, simulate, settings, faults) as (addr, sim_rig,
                                                                                 extra):
        decides = {k: v for k, v in extra.items() if k != "sim_field"}
        fingerprint = plan.fingerprint(decides)
        if resume:
            jr = Journal.resume(jpath, fingerprint, len(steps),
                                also=(plan.fingerprint(decides, legacy=True),),
                                plans=(plan.fingerprint(), plan.fingerprint(legacy=True)))
        else:  # not resuming: a journal holding no step is replaced, one with steps refused
            jr = Journal.create(jpath, fingerprint, len(steps), plan=plan.fingerprint())
        with jr:
            start = len(jr.records)
            attrs: dict[str, object] = {"journal_fingerprint": fingerprint, **extra}
            try:
                if start < len(steps):
                    inst = open_instruments(addr, plan.rig, rm)
                    try:
                        check_same_meter(jr.session.get("meter_idn"), inst.meter.idn, jpath)
                        attrs["meter_idn"] = inst.meter.idn
                        attrs["motion_version"] = inst.motion.version
                        # the journal alone must tell a rehearsal and the instruments
                        # (--from-journal, a resume with no step left): hardware.journal
                        jr.note_session({k: v for k, v in attrs.items()
                                         if k != "journal_fingerprint"})
                        acquire(plan, inst, jr, progress=progress,
                                before_step=sim_rig.set_sample if sim_rig else None)
                    finally:
                        inst.close()
                else:
                    step_progress(progress, start, len(steps))
            except BaseException:
                if not jr.records:  # failed before its first step: leave no journal behind
                    jr.close()
                    jpath.unlink(missing_ok=True)
                raise
    ds = fieldmap_from_journal(plan, jpath, attrs)
    fieldmaps.save(ds, output)
    return ScanResult(ds, output, jpath, len(steps), len(steps) - start)


def scan_files(plan: str | os.PathLike[str], output: str | os.PathLike[str], *,
               rig: str | os.PathLike[str] | None = None, journal: str | os.PathLike[str] | None = None,
               resources: list[str] | Mapping[str, str] | None = None,
               simulate: str | os.PathLike[str] | None = None, resume: bool = False,
               sim_options: Mapping[str, object] | None = None,
               progress: Progress | None = None) -> ScanResult:
    """``raysim scan`` as one call: read the plan file (``rig`` over its rig file), check the
    output against every input, apply ``sim_options`` (``seed``, ``noise_db``, ``drift_db``,
    ``centre_offset``, ``time_scale``; None values ignored, the bounds of
    :class:`~hardware.sim.settings.SimSettings`) and run :func:`scan`."""
    from hardware.plan import load_plan
    from hardware.sim.settings import with_options

    scan_plan = load_plan(plan, rig=rig)
    addresses = parse_resources(resources) if not isinstance(resources, Mapping) else dict(resources)
    _check_outputs(scan_plan, output, journal)
    settings = with_options(scan_plan.simulator, **(sim_options or {}))
    if simulate is None and sim_options and any(v is not None for v in sim_options.values()):
        raise PlanError("the simulator's options (--seed, --noise-db, --drift-db, --centre-offset, "
                        "--time-scale) apply with --simulate only")
    return scan(scan_plan, output, resources=addresses, simulate=simulate, sim=settings,
                resume=resume, journal=journal, progress=progress)


def meter_identity(idn: str) -> tuple[str, str]:
    """The (model, serial number) of an ``*IDN?`` answer (manufacturer, model, serial,
    firmware), upper case; what is missing is ''. The manufacturer (Agilent became Keysight)
    and the firmware may change on the same meter, and do not change its gain."""
    fields = [f.strip().upper() for f in idn.split(",")]
    fields += [""] * (3 - len(fields))
    return fields[1], fields[2]


def check_same_meter(recorded: object, idn: str, path: str | os.PathLike[str]) -> None:
    """Refuse (:class:`JournalError`) to resume a journal whose steps another power meter read.

    ``recorded``: the meter's ``*IDN?`` in the journal's last session line (None for a
    journal without one: nothing to compare); ``idn``: the meter connected now. Each meter has
    its own absolute gain, so readings of two meters are not on one scale. Only the model and
    serial number are compared: the same meter at another address resumes.
    """
    if not isinstance(recorded, str) or not recorded:
        return
    if meter_identity(recorded) != meter_identity(idn):
        raise JournalError(f"{path}: the journal's steps were read by the power meter "
                           f"'{recorded}', this is '{idn}': another meter has its own gain, the "
                           "two parts would not be on one scale; resume with the same meter, or "
                           "start a new scan")


def fieldmap_file_from_journal(plan: str | os.PathLike[str], output: str | os.PathLike[str], *,
                               rig: str | os.PathLike[str] | None = None,
                               journal: str | os.PathLike[str] | None = None) -> xr.Dataset:
    """``raysim scan --from-journal``: write the FieldMap of the journal as it stands (cells not
    yet measured are NaN), without a rig; refused while a scan writes the journal."""
    from hardware.plan import load_plan

    scan_plan = load_plan(plan, rig=rig)
    _check_outputs(scan_plan, output, journal)
    path = journal or journal_path(output)
    # a scan writing the journal would have its partial map written over its own output (or
    # over the finished file): refused while it holds the journal's lock
    with not_being_written(path):
        ds = fieldmap_from_journal(scan_plan, path)
        fieldmaps.save(ds, output)
    return ds


def _check_outputs(plan: ScanPlan, output: str | os.PathLike[str],
                   journal: str | os.PathLike[str] | None) -> None:
    for target in (output, journal):
        if target is not None:
            check_output(target, plan.inputs(), PlanError)
    check_output(output, [("journal", journal if journal is not None else journal_path(output))],
                 PlanError)


def journal_records(path: str | os.PathLike[str]) -> int:
    """Completed steps in the journal at ``path`` (0 when there is none, or only its header);
    raises :class:`JournalError` when the file is not a usable journal."""
    path = Path(path)
    if not path.exists() or path.stat().st_size == 0:
        return 0
    return len(read_journal(path)[1])


def fieldmap_from_journal(plan: ScanPlan, path: str | os.PathLike[str],
                          attrs: Mapping[str, object] | None = None) -> xr.Dataset:
    """The FieldMap of ``plan`` from a journal file alone (cells not yet measured are NaN), with
    the attributes its last session line records (the simulator's, the instruments'
    identities) under ``attrs``."""
    header, records, _, session, lines = read_journal_sessions(path)
    if header.get("steps") != len(plan.steps()):
        raise JournalError(f"{path}: the journal has {header.get('steps')} steps, "
                           f"the plan {len(plan.steps())}")
    check_journal_plan(plan, header, records, path, lines)
    if header.get("version", 1) >= 2 and lines and lines[0] == 2:
        # each session writes its line before its first step (hardware.journal): a step right
        # after the header lost it, and a rehearsal would read as a measurement
        raise JournalError(f"{path}: step {records[0].n} on line 2 has no session line before "
                           "it (whether the rig was simulated, the meter's identity): the journal "
                           "was cut or edited")
    # the last session's instruments (hardware.journal), under what the caller knows now
    return build_fieldmap(plan, records, {"journal_fingerprint": header.get("fingerprint", ""),
                                          **session, **(attrs or {})})


def check_journal_plan(plan: ScanPlan, header: Mapping[str, Any], records: Sequence[Record],
                       path: str | os.PathLike[str], lines: Sequence[int] = ()) -> None:
    """Refuse a journal that is not ``plan``'s: its header's plan fingerprint (journals written
    since it was recorded), and for every record the step's kind, cell and commanded axes (rad,
    to 1e-9), which the plan decides; so the readings of another grid, dish or frequency are
    never written into this plan's cells. ``lines``: each record's line in the file (default
    its step + 2, as in a journal without session lines)."""
    recorded = header.get("plan")
    if recorded and recorded not in (plan.fingerprint(), plan.fingerprint(legacy=True)):
        raise JournalError(f"{path}: the journal belongs to another plan (its plan fingerprint "
                           f"{recorded}, this plan's {plan.fingerprint()})")
    steps = plan.steps()
    for record in records:
        if record.n >= len(steps):
            raise JournalError(f"{path}: holds step {record.n}, the plan has {len(steps)} steps: "
                               "the journal is not this plan's")
        step = steps[record.n]
        command = plan.rig.axes(step.theta, step.phi)
        if (record.kind, record.i, record.j) != (step.kind, step.i, step.j) or not all(
                abs(a - b) <= 1e-9 for a, b in zip(record.command, command, strict=True)):
            raise JournalError(f"{path}: step {record.n} of the journal is not this plan's (cell or "
                               "commanded axes differ): the journal belongs to another plan")
        # the plan decides how many readings a step takes (acquire.scan): another count is a
        # hand-edited journal, whose mean and spread would be of other readings
        count = plan.reference_samples if step.kind == REFERENCE else plan.samples_per_point
        if len(record.power) != count:
            line = lines[record.n] if lines else record.n + 2
            raise JournalError(f"{path}: line {line} (step {record.n}) holds "
                               f"{len(record.power)} power readings, the plan takes {count}")


def park(rig: Rig, *, resources: Mapping[str, str] | None = None, simulate: bool = False,
         rm: pyvisa.ResourceManager | None = None) -> tuple[float, float]:
    """Move the rig to its park position; return the read-back (slider, rotation) in rad."""
    resources = dict(resources or {})
    other = sorted(set(resources) - {"motion"})
    if other:
        raise PlanError(f"rig park drives the motion controller only: --resource {other[0]}=... "
                        "does not apply (give --resource motion=VISA)")
    if simulate:
        if resources:
            raise PlanError("give either --resource or --simulate, not both")
        with SimulatedRig(rig, SimSettings(time_scale=0.0)) as sim_rig:
            return _park(rig, sim_rig.resources["motion"], rm)
    address = {**rig.resources, **resources}.get("motion")
    if address is None:
        raise PlanError("no motion controller address: give --resource motion=VISA, "
                        "[instruments] motion in the rig file, or --simulate")
    return _park(rig, address, rm)


def _park(rig: Rig, address: str, rm: pyvisa.ResourceManager | None) -> tuple[float, float]:
    motion = MotionController.open(address, timeout_s=rig.visa_timeout_s, rm=rm)
    try:
        motion.setup((rig.slider_axis, rig.rotation_axis), rig.speed)
        return move_to(motion, rig, *rig.park)
    except BaseException:
        motion.stop((rig.slider_axis, rig.rotation_axis))  # as a scan does on any failure
        raise
    finally:
        motion.close()


def open_instruments(addresses: Mapping[str, str], rig: Rig,
                     rm: pyvisa.ResourceManager | None = None) -> Instruments:
    """Open and identify both instruments (the meter first)."""
    meter = PowerMeter.open(addresses["meter"], timeout_s=rig.visa_timeout_s, rm=rm)
    try:
        motion = MotionController.open(addresses["motion"], timeout_s=rig.visa_timeout_s, rm=rm)
    except BaseException:
        meter.close()
        raise
    return Instruments(meter, motion)


@contextmanager
def _instrument_addresses(plan: ScanPlan, resources: Mapping[str, str] | None,
                          simulate: str | os.PathLike[str] | None, settings: SimSettings,
                          faults: Faults) -> Iterator[tuple[dict[str, str],
                                                            SimulatedRig | None, dict]]:
    """Addresses of the instruments (starting a simulated rig if asked), the simulator, and
    the settings that decide the samples (for the journal's fingerprint)."""
    if simulate is None:
        addr = {**plan.rig.resources, **(resources or {})}
        missing = [role for role in ROLES if role not in addr]
        if missing:
            raise PlanError(f"no address for the {missing[0]}: give --resource "
                            f"{missing[0]}=VISA, [instruments] in the rig file, or --simulate")
        yield addr, None, {"simulated": 0}
        return
    ds = fieldmaps.load(simulate)
    for name, ours in (("focal_length", plan.focal_length), ("diameter", plan.diameter)):
        if not math.isclose(float(ds.attrs[name]), ours, rel_tol=1e-9):
            raise PlanError(f"{simulate}: {name} {float(ds.attrs[name]):g} m differs from the "
                            f"plan's {ours:g} m")
    _check_probe(plan, ds, simulate)
    _check_obstacles(plan, ds, simulate)
    _check_coverage(plan, ds, simulate)
    field = SphereField.from_fieldmap(ds)
    sha = hashlib.sha256(np.ascontiguousarray(field.ratio.values).tobytes())
    if field.blocked is not None:  # a map with obstacles: their shadows decide the readings too
        sha.update(np.ascontiguousarray(field.blocked.values).tobytes())
    digest = sha.hexdigest()[:16]
    extra = {"simulated": 1, "sim_field": str(simulate), "sim_field_sha256": digest,
             **settings.record()}
    sim_rig = SimulatedRig(plan.rig, settings, field,
                           power_unit_dbm=w_to_dbm(plan.power_unit), faults=faults)
    with sim_rig:
        yield sim_rig.resources, sim_rig, extra


def _check_coverage(plan: ScanPlan, ds: xr.Dataset, simulate: str | os.PathLike[str]) -> None:
    """Refuse a FieldMap to scan that does not hold the plan (:func:`check_map_holds_plan`)."""
    check_map_holds_plan(plan, fieldmaps.grid_of(ds), float(ds.attrs["frequency_hz"]), str(simulate),
                         "simulate the scene on the rig's sphere (its radius) holding the plan's grid, at "
                         "the plan's frequency")


def check_map_holds_plan(plan: ScanPlan, grid: SphereGrid, frequency_hz: float, source: str,
                         remedy: str) -> None:
    """Refuse (PlanError) a map to scan, on ``grid`` at ``frequency_hz``, that was simulated at
    another frequency or on a sphere of another radius than the rig's track (both to 1e-9
    relative: float round trips pass) or does not hold every direction the plan reads: beyond its cells the
    simulated meter could only repeat the map's edge values (a map of theta 0..40 deg under a
    plan to 78 deg gave 108 cells of its 39 deg row, with nothing to tell them from readings).
    ``source`` names the map, ``remedy`` says what to do."""
    if not math.isclose(frequency_hz, plan.frequency_hz, rel_tol=1e-9):
        theirs, ours = distinct(frequency_hz / 1e9, plan.frequency_hz / 1e9)
        raise PlanError(f"{source} is at {theirs} GHz, the plan reads at {ours} GHz: {remedy}")
    # the map's intensities are on its sphere, (rho / R)^2 of the ideal: a map made at 3 m read
    # by a 5 m track was labelled R = 5 and inverted 52 um RMS off a 36 um map, with no word
    if not math.isclose(grid.radius, plan.rig.radius, rel_tol=1e-9):
        theirs, ours = distinct(grid.radius, plan.rig.radius)
        raise PlanError(f"{source} is on a sphere of radius {theirs} m, the rig's track has R = "
                        f"{ours} m ([track] radius_m): {remedy}")
    steps = plan.steps()
    theta = np.array([step.theta for step in steps])
    phi = np.array([step.phi for step in steps])
    slack = 1e-9  # rad: a plan cell centred on the map's edge is inside it
    outside = (theta < grid.theta_min - slack) | (theta > grid.theta_max + slack)
    if not grid.full_circle:
        along = np.mod(phi - grid.phi_min + slack, 2.0 * math.pi)
        outside |= along > grid.phi_max - grid.phi_min + 2.0 * slack
    if np.any(outside):
        first = steps[int(np.argmax(outside))]
        raise PlanError(f"{source} covers theta {math.degrees(grid.theta_min):g}.."
                        f"{math.degrees(grid.theta_max):g} deg, phi {math.degrees(grid.phi_min):g}.."
                        f"{math.degrees(grid.phi_max):g} deg; the plan reads {int(outside.sum())} "
                        f"steps outside it (the first at theta {math.degrees(first.theta):g} deg, phi "
                        f"{math.degrees(first.phi):g} deg): {remedy}")


def distinct(a: float, b: float) -> tuple[str, str]:
    """``a`` and ``b`` written with the fewest significant digits (6 at least, 17 at most)
    that tell them apart: '3 GHz, the plan 3 GHz' hid a plan at 3.0000001 GHz."""
    for digits in range(6, 18):
        first, second = f"{a:.{digits}g}", f"{b:.{digits}g}"
        if first != second:
            return first, second
    return repr(a), repr(b)


def _check_probe(plan: ScanPlan, ds: xr.Dataset, simulate: str | os.PathLike[str]) -> None:
    """Refuse a FieldMap to scan that another probe measured: the simulated meter reads the
    map's intensity, which is what the map's probe reads (raysim.maps.probe), so it must be
    the rig's probe, and a polarised one under the plan's incident polarisation."""
    theirs, ours = probe_of(ds, str(simulate)), plan.rig.probe_response
    if theirs != ours:
        raise PlanError(f"{simulate} was simulated with the probe '{theirs.describe()}', the rig "
                        f"has '{ours.describe()}': simulate the scene with the rig's [probe]")
    pol = float(ds.attrs.get("polarization", 0.0))
    if ours.polarization is not None and not math.isclose(pol, plan.polarization, abs_tol=1e-12):
        raise PlanError(f"{simulate} has the incident wave polarised at {math.degrees(pol):g} deg, "
                        f"the plan at {math.degrees(plan.polarization):g} deg "
                        "([reflector] polarization_deg)")


def _check_obstacles(plan: ScanPlan, ds: xr.Dataset, simulate: str | os.PathLike[str]) -> None:
    """Refuse a FieldMap to scan whose obstacles (its ``obstacle_vertices``, ``obstacle_faces``)
    are not the plan's: the measured map marks the cells the plan's obstacles hide, so the
    telescope scanned must have those in its beam."""
    mesh = plan.obstacle_mesh
    has = "obstacle_vertices" in ds.data_vars and "obstacle_faces" in ds.data_vars
    theirs = str(ds.attrs.get("obstacles", "triangles"))
    if mesh is None and not has:
        return
    if mesh is None:
        raise PlanError(f"{simulate} has obstacles in the beam ({theirs}), the plan none: give "
                        "the plan the scene's [[obstacle]] tables")
    if not has:
        raise PlanError(f"{simulate} has no obstacles in the beam, the plan has "
                        f"{mesh.description}: simulate the scene with the plan's [[obstacle]] tables")
    same = (ds["obstacle_vertices"].shape == mesh.vertices.shape
            and ds["obstacle_faces"].shape == mesh.faces.shape
            and np.allclose(ds["obstacle_vertices"].values, mesh.vertices, rtol=0.0, atol=1e-9)
            and np.array_equal(ds["obstacle_faces"].values, mesh.faces))
    if not same:
        raise PlanError(f"{simulate} has other obstacles in the beam ({theirs}) than the plan "
                        f"({mesh.description}): give both the same [[obstacle]] tables")
