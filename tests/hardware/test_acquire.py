"""Whole scans through the API against the simulated rig: values, drift, calibration, resume."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from hardware.errors import JournalError, PlanError
from hardware.journal import Record, read_journal
from hardware.plan import REFERENCE, ScanPlan, load_plan
from hardware.rig import Calibration, Rig
from hardware.session import fieldmap_file_from_journal, fieldmap_from_journal, park, scan
from hardware.sim.rig import Faults
from hardware.sim.settings import drift_db
from raysim.errors import InstrumentError
from raysim.maps import fieldmap as fieldmaps
from raysim.maps.sphere import SphereGrid, ideal_go_intensity

from .conftest import D, F, R, pattern, write_field, write_plan

# the plans' grid: 3 x 6 cells of 20 x 60 deg
PLAN_GRID = SphereGrid(R, 3, 6, 0.0, math.radians(60.0), 0.0, 2 * math.pi)


def aligned_field(tmp_path: Path) -> Path:
    """The pattern on the plan's own grid: every probe position is a stored cell centre."""
    return write_field(tmp_path / "aligned.nc", PLAN_GRID)


def expected_pattern() -> np.ndarray:
    t, p = np.meshgrid(PLAN_GRID.theta, PLAN_GRID.phi, indexing="ij")
    return pattern(t, p)


def test_scan_measures_the_field(tmp_path: Path) -> None:
    plan = load_plan(write_plan(tmp_path))
    result = scan(plan, tmp_path / "scan.nc", simulate=aligned_field(tmp_path))
    ds = fieldmaps.load(result.output)
    assert ds.attrs["method"] == "measured" and ds.attrs["sampling"] == "centre"
    assert ds.attrs["sphere_radius"] == R and ds.attrs["focal_length"] == F
    assert np.allclose(ds["intensity"].values, expected_pattern(), rtol=1e-9, atol=0)
    # the ideal is the paraboloid's GO law (rho / R)^2, rho = 2F / (1 + cos theta), at the cell
    # centres (all inside the rim image, 79.6 deg); written out, not taken from raysim
    ideal = (2 * F / (1 + np.cos(PLAN_GRID.theta)) / R) ** 2
    np.testing.assert_allclose(ds["intensity_ideal"].values, np.repeat(ideal[:, None], 6, axis=1),
                               rtol=1e-12, atol=0)
    assert np.allclose(ds["intensity_std"].values, 0.0, atol=1e-12)
    assert np.allclose(ds["slider_readback"], ds["slider_command"], atol=1e-7)
    assert np.allclose(ds["r_probe"], R, atol=1e-12)
    assert ds.sizes["reference"] == 4
    assert sorted(ds["sample_index"].values.ravel()) == [n for n in range(22)
                                                         if n not in (0, 7, 14, 21)]
    assert result.steps_taken == result.steps_total == 22


def test_an_unknown_receiver_gain_scales_every_reading(tmp_path: Path) -> None:
    """gain_db is what power_unit_dbm does not know: every intensity is off by it, drift
    references included, so the scan's scale is unknown (and estimated when inverted)."""
    plan = load_plan(write_plan(tmp_path))
    plan = dataclasses.replace(plan, simulator=dataclasses.replace(plan.simulator, gain_db=0.4))
    ds = scan(plan, tmp_path / "scan.nc", simulate=aligned_field(tmp_path)).fieldmap
    assert np.allclose(ds["intensity"].values, expected_pattern() * 10 ** 0.04, rtol=1e-9, atol=0)
    assert ds.attrs["sim_gain_db"] == 0.4


def test_references_remove_the_drift(tmp_path: Path) -> None:
    """With drift and no noise, what remains is the drift's departure from its linear
    interpolation between the reference readings."""
    plan = load_plan(write_plan(tmp_path, drift=0.2, drift_correction="linear"))
    ds = scan(plan, tmp_path / "scan.nc", simulate=aligned_field(tmp_path)).fieldmap
    settings = plan.simulator
    refs = [s.index for s in plan.steps() if s.kind == REFERENCE]
    gains = [10 ** (drift_db(settings, n) / 10) for n in refs]
    n = ds["sample_index"].values
    true_gain = 10 ** (np.vectorize(lambda k: drift_db(settings, k))(n) / 10)
    estimate = np.interp(n, refs, gains)
    expected = expected_pattern() * true_gain / estimate
    assert np.allclose(ds["intensity"].values, expected, rtol=1e-9, atol=0)
    # the drift was large and is mostly gone
    raw = np.abs(true_gain - 1).max()
    left = np.abs(ds["intensity"].values / expected_pattern() - 1).max()
    assert raw > 0.02 and left < raw / 5


def test_auto_drift_correction_follows_the_references(tmp_path: Path) -> None:
    field = aligned_field(tmp_path)
    quiet = load_plan(write_plan(tmp_path / "a", noise=0.01, reference_samples=16,
                                 drift_correction="auto"))
    ds = scan(quiet, tmp_path / "a.nc", simulate=field).fieldmap
    assert ds.attrs["drift_correction_applied"] == "none"
    assert ds.attrs["drift_chi2"] < ds.attrs["drift_chi2_limit"]
    assert np.all(ds["drift_db"].values == 0.0)
    drifting = load_plan(write_plan(tmp_path / "b", noise=0.01, drift=0.3, reference_samples=16,
                                    drift_correction="auto"))
    ds = scan(drifting, tmp_path / "b.nc", simulate=field).fieldmap
    # leave-one-out picks a smoothing; its lines miss these few references by more than their
    # noise, so they are followed as read (hardware.drift.widest_consistent), and it says so
    assert ds.attrs["drift_correction_applied"] == "linear"
    assert "followed the references (linear)" in ds.attrs["drift_note"]
    assert ds.attrs["drift_chi2"] > 100 * ds.attrs["drift_chi2_limit"]


def bilinear(theta, phi):
    """A ratio to the ideal that bilinear interpolation reproduces exactly (rad in)."""
    return 1.0 + 0.3 * theta + 0.02 * phi + 0.01 * theta * phi


def test_unknown_centre_offset_biases_a_known_one_does_not(tmp_path: Path) -> None:
    """The track centre is really 2 mm off the focus (axially and sideways)."""
    plan = load_plan(write_plan(tmp_path))
    truth = (0.0015, 0.0, 0.002)
    sim = dataclasses.replace(plan.simulator, centre_offset=truth)
    # 4 x 12 deg cells: the plan's centres are among theirs, bilinear values everywhere
    grid = SphereGrid(R, 22, 30, 0.0, math.radians(88.0), 0.0, 2 * math.pi)
    t, p = np.meshgrid(grid.theta, grid.phi, indexing="ij")
    ideal = ideal_go_intensity(t, F, R, D)
    field = write_field(tmp_path / "bilinear.nc", grid, bilinear(t, p) * ideal)
    unknown = scan(plan, tmp_path / "a.nc", simulate=field, sim=sim).fieldmap
    # the probe at axes (s, a) really sits at c + R u: the field there times (R / r)^2
    expected = np.empty((3, 6))
    for i, theta in enumerate(PLAN_GRID.theta):
        for j, phi in enumerate(PLAN_GRID.phi):
            # the controller positions to 1e-6 deg
            s, a = (math.radians(round(math.degrees(v), 6)) for v in plan.rig.axes(theta, phi))
            q = np.array(truth) + R * np.array([math.sin(s) * math.cos(a),
                                                math.sin(s) * math.sin(a), -math.cos(s)])
            r = np.linalg.norm(q)
            t_true = math.atan2(math.hypot(q[0], q[1]), -q[2])
            p_true = math.atan2(q[1], q[0]) % (2 * math.pi)
            ideal = (2 * F / (1 + math.cos(t_true)) / R) ** 2
            expected[i, j] = bilinear(t_true, p_true) * ideal * (R / r) ** 2
    # the meter answers with 10 digits (1e-8 dB): 2.3e-9 relative
    assert np.allclose(unknown["intensity"].values, expected, rtol=5e-9, atol=0)
    t, p = np.meshgrid(PLAN_GRID.theta, PLAN_GRID.phi, indexing="ij")
    commanded = bilinear(t, p) * ideal_go_intensity(t, F, R, D)
    assert np.abs(unknown["intensity"].values / commanded - 1).max() > 2e-4

    known_rig = plan.rig.with_calibration(Calibration(centre_offset=truth))
    known_plan = dataclasses.replace(plan, rig=known_rig)
    known = scan(known_plan, tmp_path / "b.nc", simulate=field, sim=sim).fieldmap
    # commanded along the ray from the focus and referred back to the sphere: no bias
    # (beyond the controller's 1e-6 deg resolution)
    assert np.allclose(known["intensity"].values, commanded, rtol=1e-7, atol=0)
    assert not np.allclose(known["r_probe"].values, R, atol=1e-4)


def test_fault_then_resume_equals_uninterrupted(tmp_path: Path) -> None:
    plan = load_plan(write_plan(tmp_path, noise=0.02, drift=0.1))
    field = aligned_field(tmp_path)
    whole = scan(plan, tmp_path / "whole.nc", simulate=field).fieldmap
    out = tmp_path / "parts.nc"
    journal = tmp_path / "parts.nc.journal"
    # two moves a step; move 10 turns the track for step 4, the first of line 1:
    # steps 0-3 complete
    with pytest.raises(InstrumentError, match="axis 2 stopped at"):
        scan(plan, out, simulate=field, faults=Faults(stall_at_move=10))
    assert [r.n for r in read_journal(journal)[1]] == [0, 1, 2, 3]
    partial = fieldmap_from_journal(plan, journal)
    assert int(np.isfinite(partial["intensity"].values).sum()) == 3
    # the meter fails at its 5th reading (two a step): steps 0 and 1 of this run complete
    with pytest.raises(InstrumentError, match="-241"):
        scan(plan, out, simulate=field, resume=True, faults=Faults(meter_error_at_reading=5))
    assert len(read_journal(journal)[1]) == 6
    result = scan(plan, out, simulate=field, resume=True)
    assert result.steps_taken == 22 - 6
    for name in whole.data_vars:
        if name in ("time", "reference_time"):
            continue
        assert np.array_equal(whole[name].values, result.fieldmap[name].values,
                              equal_nan=True), name
    assert np.isfinite(whole["intensity"].values).all()


def test_a_resume_with_another_power_meter_is_refused_the_same_one_resumes(tmp_path: Path) -> None:
    """QA: a resume against another meter (other model and serial) was merged silently and the
    FieldMap named only the second; each meter has its own gain, so the halves are not on
    one scale. The same meter resumes, though at another address (each simulated rig here
    listens on a new port) and with other firmware."""
    from hardware.sim.instruments import METER_IDN

    plan = load_plan(write_plan(tmp_path))
    field = aligned_field(tmp_path)
    out = tmp_path / "s.nc"
    journal = tmp_path / "s.nc.journal"
    with pytest.raises(InstrumentError, match="axis 2 stopped at"):
        scan(plan, out, simulate=field, faults=Faults(stall_at_move=10))
    before = journal.read_bytes()
    other = "Keysight Technologies,N1914A,OTHER-SERIAL,B9"
    with pytest.raises(JournalError) as info:
        scan(plan, out, simulate=field, resume=True, faults=Faults(meter_idn=other))
    message = str(info.value)
    assert "\n" not in message and METER_IDN in message and other in message
    assert journal.read_bytes() == before and not out.exists()
    # the same model and serial number, its firmware updated: the same meter
    maker, model, serial, _ = METER_IDN.split(",")
    updated = f"{maker},{model},{serial},A9.99.99"
    result = scan(plan, out, simulate=field, resume=True, faults=Faults(meter_idn=updated))
    assert result.steps_taken == 22 - 4
    assert result.fieldmap.attrs["meter_idn"] == updated


@pytest.mark.parametrize("tolerance_deg", [10.0, 35.0])
def test_a_move_tolerance_of_half_the_grid_step_or_more_is_refused_before_any_move(
        tmp_path: Path, tolerance_deg: float) -> None:
    """QA: a tolerance wider than half the grid step let a stalled move pass, its reading
    stored in the wrong cell with exit 0. The plan's steps are 20 deg (theta) and 60 deg
    (phi): half the smallest is 10 deg. Move 10 turns the track 60 deg for step 4 and stalls
    30 deg short, which 35 deg passed."""
    from hardware.sim.rig import SimulatedRig
    from hardware.sim.settings import SimSettings

    plan_path = write_plan(tmp_path)
    rig_toml = tmp_path / "rig.toml"
    rig_toml.write_text(rig_toml.read_text().replace("tolerance_deg = 0.001",
                                                     f"tolerance_deg = {tolerance_deg}"))
    plan = load_plan(plan_path)
    out = tmp_path / "s.nc"
    with SimulatedRig(plan.rig, SimSettings(time_scale=0.0),
                      faults=Faults(stall_at_move=10)) as sim:
        with pytest.raises(PlanError) as info:
            scan(plan, out, resources=sim.resources)
        assert sim.motion.moves == 0 and sim.meter.readings == 0
    message = str(info.value)
    assert "\n" not in message
    assert f"tolerance_deg {tolerance_deg:g} deg" in message and "= 10 deg" in message
    assert not out.exists() and not (tmp_path / "s.nc.journal").exists()
    # just below half a step is accepted
    rig_toml.write_text(rig_toml.read_text().replace(f"tolerance_deg = {tolerance_deg}",
                                                     "tolerance_deg = 9.99"))
    load_plan(plan_path).check_tolerance()


def test_journal_guards(tmp_path: Path) -> None:
    plan = load_plan(write_plan(tmp_path, noise=0.01))
    field = aligned_field(tmp_path)
    out = tmp_path / "scan.nc"
    scan(plan, out, simulate=field)
    journal = tmp_path / "scan.nc.journal"
    before = journal.read_bytes()
    with pytest.raises(JournalError, match="pass --resume"):
        scan(plan, out, simulate=field)
    noisier = dataclasses.replace(plan.simulator, noise_db=0.02)
    with pytest.raises(JournalError, match="other settings of the simulated rig"):
        scan(plan, out, simulate=field, sim=noisier, resume=True)
    more = dataclasses.replace(plan, samples_per_point=plan.samples_per_point + 1)
    with pytest.raises(JournalError, match="belongs to another plan"):
        scan(more, out, simulate=field, resume=True)
    assert journal.read_bytes() == before
    # resuming a complete journal only rewrites the FieldMap
    again = scan(plan, out, simulate=field, resume=True)
    assert again.steps_taken == 0


def test_a_map_that_does_not_hold_the_plan_is_not_scanned(tmp_path: Path) -> None:
    """A map short of the plan's grid was scanned to the end, the cells beyond it filled with
    the map's edge values (a 0..40 deg map under a 0..60 deg plan: its last row repeated, exit
    0), and a map of another frequency was scanned as the plan's. Both are refused in one line
    before any step, and no journal is left; a map of exactly the plan's grid is scanned."""
    plan = load_plan(write_plan(tmp_path))  # theta 0..60 deg in 20 deg cells, phi 0..360 deg
    cases = {
        "short.nc": (SphereGrid(R, 4, 6, 0.0, math.radians(40.0)), "the plan reads 6 steps outside it \\(the first at theta 50 deg"),
        "half.nc": (SphereGrid(R, 3, 3, 0.0, math.radians(60.0), 0.0, math.pi), "steps outside it"),
    }
    for name, (grid, words) in cases.items():
        with pytest.raises(PlanError, match=words):
            scan(plan, tmp_path / "o.nc", simulate=write_field(tmp_path / name, grid))
        assert not (tmp_path / "o.nc.journal").exists() and not (tmp_path / "o.nc").exists()
    other = dataclasses.replace(plan, frequency_hz=2.0 * plan.frequency_hz)
    with pytest.raises(PlanError, match="is at 0.3 GHz, the plan reads at 0.6 GHz"):
        scan(other, tmp_path / "o.nc", simulate=aligned_field(tmp_path))
    assert scan(plan, tmp_path / "o.nc", simulate=aligned_field(tmp_path)).steps_taken == len(plan.steps())


def test_a_map_on_another_sphere_or_a_hair_off_in_frequency_is_refused_saying_so(tmp_path: Path) -> None:
    """QA: a map made at R = 3 m scanned by a 5 m track gave a FieldMap labelled R = 5 holding
    R = 3 intensities (the inverted map 52 um RMS off a 36 um map), exit 0; and a plan at
    3.0000001 GHz against a 3 GHz map was refused as 'at 3 GHz, the plan reads at 3 GHz'.
    The radius is refused like the frequency, and both lines show the numbers that differ; a
    radius or frequency off by float round-off still scans."""
    plan = load_plan(write_plan(tmp_path))
    grid = SphereGrid(R, 3, 6, 0.0, math.radians(60.0))
    wider = write_field(tmp_path / "wide.nc", dataclasses.replace(grid, radius=0.6 * R))
    with pytest.raises(PlanError, match=f"radius {0.6 * R:g} m, the rig's track has R = {R:g} m"):
        scan(plan, tmp_path / "o.nc", simulate=wider)
    assert not (tmp_path / "o.nc.journal").exists() and not (tmp_path / "o.nc").exists()
    hair = dataclasses.replace(plan, frequency_hz=plan.frequency_hz * (1.0 + 1e-7 / 3.0))
    with pytest.raises(PlanError, match=r"is at 0\.3 GHz, the plan reads at 0\.30000001 GHz"):
        scan(hair, tmp_path / "o.nc", simulate=aligned_field(tmp_path))
    close = write_field(tmp_path / "close.nc", dataclasses.replace(grid, radius=R * (1.0 + 1e-13)))
    assert scan(plan, tmp_path / "o.nc", simulate=close).steps_taken == len(plan.steps())


def test_simulated_field_must_match_the_plan(tmp_path: Path) -> None:
    plan = load_plan(write_plan(tmp_path))
    other = dataclasses.replace(plan, focal_length=40.0)
    with pytest.raises(PlanError, match="focal_length 33 m differs"):
        scan(other, tmp_path / "scan.nc", simulate=aligned_field(tmp_path))
    with pytest.raises(PlanError, match="either --resource or --simulate"):
        scan(plan, tmp_path / "scan.nc", simulate=aligned_field(tmp_path),
             resources={"meter": "TCPIP::127.0.0.1::1::SOCKET"})
    with pytest.raises(PlanError, match="no address for the meter"):
        scan(plan, tmp_path / "scan.nc")


def test_park_simulated() -> None:
    rig = Rig(radius=R, park=(math.radians(93.0), math.radians(10.0)))
    slider, rotation = park(rig, simulate=True)
    assert math.degrees(slider) == pytest.approx(93.0, abs=1e-6)
    assert math.degrees(rotation) == pytest.approx(10.0, abs=1e-6)


def test_a_journal_is_rebuilt_only_by_its_own_plan(tmp_path: Path) -> None:
    from hardware.journal import _with_crc

    plan_path = write_plan(tmp_path, noise=0.01)
    plan = load_plan(plan_path)
    field = aligned_field(tmp_path)
    scan(plan, tmp_path / "scan.nc", simulate=field)
    journal = tmp_path / "scan.nc.journal"
    same = fieldmap_from_journal(plan, journal)
    assert np.isfinite(same["intensity"].values).all()
    before = journal.read_bytes()
    with pytest.raises(PlanError, match="is the journal"):  # the FieldMap written over its journal
        fieldmap_file_from_journal(plan_path, journal, journal=journal)
    assert journal.read_bytes() == before
    # the same number of steps, another grid (shifted 5 deg), another frequency: refused
    shifted = dataclasses.replace(plan, grid=dataclasses.replace(
        plan.grid, theta_min=math.radians(5.0), theta_max=plan.grid.theta_max + math.radians(5.0)))
    higher = dataclasses.replace(plan, frequency_hz=6e8)
    assert len(shifted.steps()) == len(higher.steps()) == len(plan.steps())
    for other in (shifted, higher):
        with pytest.raises(JournalError, match="belongs to another plan"):
            fieldmap_from_journal(other, journal)
    # a journal written before headers carried the plan's fingerprint: the records' cells and
    # commanded axes still tell the shifted grid
    lines = journal.read_bytes().splitlines(keepends=True)
    header = json.loads(lines[0])
    del header["plan"], header["crc"]
    old = tmp_path / "old.journal"
    old.write_bytes(_with_crc(header) + b"".join(lines[1:]))
    assert np.array_equal(fieldmap_from_journal(plan, old)["intensity"].values,
                          same["intensity"].values)
    with pytest.raises(JournalError, match="of the journal is not this plan's"):
        fieldmap_from_journal(shifted, old)


def test_a_journal_being_written_is_not_taken_by_a_second_scan(tmp_path: Path) -> None:
    from hardware.journal import Journal

    path = tmp_path / "scan.nc.journal"
    with Journal.create(path, "abc", 4) as first:
        # a journal holding only its header is replaced by a new scan, but not while its own
        # scan still writes it
        with pytest.raises(JournalError, match="another scan is writing this journal"):
            Journal.create(path, "abc", 4)
        first.append(Record(0, "cell", 0, 0, (0.0, 0.0), (0.0, 0.0), (1e-3,), 0.0))
        with pytest.raises(JournalError, match="another scan is writing this journal"):
            Journal.resume(path, "abc", 4)
        before = path.read_bytes()
    # its records were kept; closed, it can be resumed
    assert path.read_bytes() == before and len(read_journal(path)[1]) == 1
    with Journal.resume(path, "abc", 4) as again:
        assert len(again.records) == 1


def test_a_resume_after_a_longer_timeout_or_a_slower_axis_continues_the_scan(tmp_path: Path,
                                                                             monkeypatch) -> None:
    """A scan stopped by an instrument fault is resumed after the crew lengthened a timeout or
    slowed the axes (what the fault's message suggests): those settings decide how a step is
    reached, never what it reads. It was refused as "another plan or other settings". A change
    of what the readings are (the simulator's noise) is still refused, and says so; a journal
    whose fingerprint an earlier raysim wrote (those settings in it) still resumes under the
    settings it was made with."""
    plan = load_plan(write_plan(tmp_path, noise=0.02, drift=0.1))
    field = aligned_field(tmp_path)
    whole = scan(plan, tmp_path / "whole.nc", simulate=field).fieldmap
    patient = dataclasses.replace(plan, rig=dataclasses.replace(
        plan.rig, move_timeout_s=2.0 * plan.rig.move_timeout_s, visa_timeout_s=5.0,
        speed=0.5 * plan.rig.speed))
    slower_sim = dataclasses.replace(plan.simulator, time_scale=1e-3)  # was 0: instant moves
    real = ScanPlan.fingerprint
    for legacy in (False, True):
        out = tmp_path / f"parts{int(legacy)}.nc"
        if legacy:  # the fingerprint as raysim wrote it before: timeouts, speed, time scale in
            with monkeypatch.context() as m:
                m.setattr(ScanPlan, "fingerprint", lambda self, extra=None, legacy=False:
                          real(self, extra, legacy=True))
                with pytest.raises(InstrumentError, match="axis 2 stopped at"):
                    scan(plan, out, simulate=field, faults=Faults(stall_at_move=10))
        else:
            with pytest.raises(InstrumentError, match="axis 2 stopped at"):
                scan(plan, out, simulate=field, faults=Faults(stall_at_move=10))
        # an earlier raysim's journal resumes under the settings it was made with
        resumer, sim = (plan, plan.simulator) if legacy else (patient, slower_sim)
        noisier = dataclasses.replace(plan.simulator, noise_db=0.03)
        with pytest.raises(JournalError, match="other settings of the simulated rig"):
            scan(resumer, out, simulate=field, sim=noisier, resume=True)
        result = scan(resumer, out, simulate=field, sim=sim, resume=True)
        assert result.steps_taken == 22 - 4
        for name in whole.data_vars:
            if name not in ("time", "reference_time"):
                assert np.array_equal(whole[name].values, result.fieldmap[name].values,
                                      equal_nan=True), name


def test_a_true_centre_offset_beyond_the_track_and_a_journal_longer_than_the_plan_are_refused(
        tmp_path: Path) -> None:
    """The simulator's true centre offset had no bound: 15 m on a 10 m track gave a divide by
    zero and a FieldMap of nothing, exit 0. A journal holding a step past the plan's last gave
    an IndexError traceback. Both are refused in one line."""
    plan = load_plan(write_plan(tmp_path))
    field = aligned_field(tmp_path)
    far = dataclasses.replace(plan.simulator, centre_offset=(0.0, 0.0, 0.5 * R))
    with pytest.raises(PlanError, match="centre_offset .* must lie well inside the track"):
        scan(plan, tmp_path / "far.nc", simulate=field, sim=far)
    assert not (tmp_path / "far.nc.journal").exists()
    out = tmp_path / "scan.nc"
    scan(plan, out, simulate=field)
    journal = tmp_path / "scan.nc.journal"
    last = read_journal(journal)[1][-1]
    with open(journal, "ab") as handle:
        handle.write(dataclasses.replace(last, n=last.n + 1).line())
    with pytest.raises(JournalError, match=f"holds step {last.n + 1}, the plan has {last.n + 1} steps"):
        fieldmap_from_journal(plan, journal)


def test_a_journal_alone_gives_the_fieldmap_the_scans_attributes(tmp_path: Path) -> None:
    """QA: a FieldMap rebuilt by --from-journal from a simulated rig's journal lost
    `simulated` and every `sim_*` attribute (a rehearsal read as a measurement), and a resume
    with no step left dropped `meter_idn` and `motion_version`. The journal records them, so
    both give the original's attributes; a journal from before (no session line) still
    resumes and assembles."""
    from hardware.journal import _with_crc
    from hardware.session import fieldmap_file_from_journal

    plan_path = write_plan(tmp_path)
    plan = load_plan(plan_path)
    field = aligned_field(tmp_path)
    out = tmp_path / "s.nc"
    original = scan(plan, out, simulate=field).fieldmap.attrs
    assert original["simulated"] == 1 and "sim_seed" in original and original["meter_idn"]
    journal = tmp_path / "s.nc.journal"
    rebuilt = fieldmap_file_from_journal(plan_path, tmp_path / "r.nc", journal=journal).attrs
    again = scan(plan, out, simulate=field, resume=True)
    assert again.steps_taken == 0
    stamps = {"created", "date_created", "history"}  # when written, not what was measured

    def same(attrs: dict) -> dict:
        return {k: v for k, v in attrs.items() if k not in stamps}

    for attrs in (rebuilt, again.fieldmap.attrs):
        assert set(same(attrs)) == set(same(original))
        for key, value in same(original).items():
            assert np.array_equal(attrs[key], value, equal_nan=isinstance(value, float)), key
    # the session line cut from this (version 2) journal: refused, not a measurement
    lines = journal.read_bytes().splitlines(keepends=True)
    old = [line for line in lines if not line.startswith(b'{"session"')]
    assert len(old) == len(lines) - 1
    cut = tmp_path / "cut.journal"
    cut.write_bytes(b"".join(old))
    with pytest.raises(JournalError, match="no session line before it"):
        fieldmap_file_from_journal(plan_path, tmp_path / "c.nc", journal=cut)
    assert not (tmp_path / "c.nc").exists()
    # a journal an earlier raysim wrote: no session line; it resumes and assembles as before
    header = {**read_journal(journal)[0], "version": 1}
    journal.write_bytes(_with_crc(header) + b"".join(old[1:]))
    assert read_journal(journal)[0]["version"] == 1
    assert "simulated" not in fieldmap_file_from_journal(plan_path, tmp_path / "o.nc", journal=journal).attrs
    assert scan(plan, out, simulate=field, resume=True).fieldmap.attrs["simulated"] == 1
