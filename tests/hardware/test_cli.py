"""``raysim scan`` and ``raysim rig park`` as a user runs them.

Real subprocesses for a full scan, a fault followed by a resume and the park command; the
other error paths run ``raysim.cli.main`` in this process (same code, faster).
"""

from __future__ import annotations

import re
import socket
from pathlib import Path

import numpy as np
import pytest

from hardware.journal import read_journal
from hardware.plan import load_plan
from hardware.sim.rig import Faults, SimulatedRig
from hardware.sim.settings import SimSettings
from raysim.maps import fieldmap as fieldmaps

from .conftest import ROOT, error_line, run_cli, write_plan


@pytest.mark.slow
def test_demo_plan_scans_a_field(tmp_path: Path, fine_field: Path, raysim_main) -> None:
    out = tmp_path / "demo.nc"
    done = run_cli("scan", str(ROOT / "scenes" / "scan_demo.toml"), "--simulate",
                   str(fine_field), "-o", str(out), "--time-scale", "0")
    assert done.returncode == 0, done.stderr
    assert "wrote" in done.stdout
    ds = fieldmaps.load(out)
    assert ds.attrs["samples_measured"] == 96 and ds.attrs["sim_noise_db"] == 0.01
    ratio = ds["intensity"].values / ds["intensity_ideal"].values
    # the pattern departs from the ideal by < 0.6 %, noise and drift add < 0.5 %
    assert np.all(np.abs(ratio - 1) < 0.011)
    assert len(read_journal(Path(str(out) + ".journal"))[1]) == 101
    # the same FieldMap follows from the journal alone
    again = tmp_path / "again.nc"
    code, _, err = raysim_main("scan", str(ROOT / "scenes" / "scan_demo.toml"), "-o", str(again),
                               "--journal", str(out) + ".journal", "--from-journal")
    assert code == 0, err
    assert np.array_equal(fieldmaps.load(again)["intensity"].values, ds["intensity"].values)


def closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


FAULTS = [
    (Faults(meter_silent=True), 0, r"power meter at TCPIP::127\.0\.0\.1::\d+::SOCKET is silent"),
    (Faults(motion_silent=True), 0, r"motion controller at .* is silent: no answer to 'VE\?'"),
    (Faults(meter_idn="Keysight Technologies,N9020A,1,1"), 0, "expected a Keysight N1913A"),
    # accepts UNIT:POW DBM and reads on in W: refused before the first reading
    (Faults(meter_fixed_unit="W"), 0,
     r"power meter 'Keysight Technologies,N1913A,MY53100001,[^']*' at .* reports unit 'W' "
     r"after 'UNIT:POW DBM'"),
    # two readings a step: the 7th reading belongs to step 3
    (Faults(meter_error_at_reading=7), 3, r"reports error -241,\"Hardware missing"),
]


def resource_args(sim: SimulatedRig) -> list[str]:
    return [f"--resource=meter={sim.resources['meter']}",
            f"--resource=motion={sim.resources['motion']}"]


def check_journal(out: Path, complete: int) -> None:
    """The journal holds exactly the steps completed before the fault, nothing torn; a scan
    that failed before its first step leaves no journal (it would block the next run)."""
    path = Path(str(out) + ".journal")
    if complete == 0:
        assert not path.exists()
        return
    _, records, good = read_journal(path)
    assert [r.n for r in records] == list(range(complete))
    assert good == path.stat().st_size


@pytest.mark.parametrize(("faults", "complete", "message"), FAULTS)
def test_instrument_faults_end_in_one_line(tmp_path: Path, raysim_main, faults: Faults,
                                           complete: int, message: str) -> None:
    plan_path = write_plan(tmp_path, visa_timeout=0.3)
    plan = load_plan(plan_path)
    out = tmp_path / "scan.nc"
    with SimulatedRig(plan.rig, SimSettings(time_scale=0.0), faults=faults) as sim:
        code, _, err = raysim_main("scan", str(plan_path), "-o", str(out), *resource_args(sim))
    assert code == 2, err
    assert error_line(err).startswith("error: ")
    assert re.search(message, err), err
    assert not out.exists()
    check_journal(out, complete)


@pytest.mark.slow
def test_stalled_move_then_resume(tmp_path: Path) -> None:
    """The real command: a move that stops short ends the scan with one line and status 2;
    the same command with --resume on a healthy rig finishes it."""
    plan_path = write_plan(tmp_path, visa_timeout=0.3)
    plan = load_plan(plan_path)
    out = tmp_path / "scan.nc"
    # two moves a step: move 10 turns the track for step 4
    with SimulatedRig(plan.rig, SimSettings(time_scale=0.0),
                      faults=Faults(stall_at_move=10)) as sim:
        done = run_cli("scan", str(plan_path), "-o", str(out), *resource_args(sim))
    assert done.returncode == 2, done.stderr
    assert re.search(r"axis 2 stopped at \d+\.\d+ deg, target 90\.0000 deg",
                     error_line(done.stderr))
    check_journal(out, 4)
    with SimulatedRig(plan.rig, SimSettings(time_scale=0.0)) as sim:
        done = run_cli("scan", str(plan_path), "-o", str(out), "--resume", *resource_args(sim))
    assert done.returncode == 0, done.stderr
    assert "18 of 22 steps taken now" in done.stdout.replace("\n", " ")
    assert fieldmaps.load(out).attrs["samples_measured"] == 18


def test_unreachable_instrument(tmp_path: Path, raysim_main) -> None:
    plan_path = write_plan(tmp_path)
    port = closed_port()
    code, _, err = raysim_main("scan", str(plan_path), "-o", str(tmp_path / "s.nc"),
                               f"--resource=meter=TCPIP::127.0.0.1::{port}::SOCKET",
                               f"--resource=motion=TCPIP::127.0.0.1::{port}::SOCKET")
    assert code == 2
    assert "power meter at" in error_line(err) and "unreachable" in err


def test_an_interrupt_before_the_first_step_says_no_journal_was_kept(tmp_path: Path, raysim_main,
                                                                      fine_field: Path, monkeypatch):
    """Ctrl-C while the instruments were opened: the session removes the journal it had just
    made, and the line said "0 of 0 steps are in s.nc.journal", naming a file that was gone."""
    import logging
    import signal

    import hardware.session
    from raysim import cli

    def interrupted(*args, **kwargs):
        cli._on_signal(signal.SIGINT, None)  # what Ctrl-C runs in the command's process

    monkeypatch.setattr(hardware.session, "open_instruments", interrupted)
    out = tmp_path / "s.nc"
    try:
        code, _, err = raysim_main("scan", str(write_plan(tmp_path)), "-o", str(out), "--simulate",
                                   str(fine_field))
    finally:
        logging.disable(logging.NOTSET)  # the signal handler silences logging for the exit
    assert code == 130 and not Path(str(out) + ".journal").exists() and not out.exists()
    assert f"(no step taken, no journal kept at {out}.journal)" in err and "0 of 0" not in err
    # nothing is there to resume (a --resume would be refused): the line must not offer one
    assert "resume" not in error_line(err).replace("interrupted:", "")


def test_resume_without_a_journal_is_refused(tmp_path: Path, raysim_main, fine_field: Path) -> None:
    """QA: --resume with no journal at the path it resumes re-scanned everything from the
    first step (hours on a real rig), leaving the real journal (given with --journal the
    first time) orphaned. It is refused in one line before any instrument is opened; the
    real journal resumes, and a journal holding only its header is nothing to resume either."""
    plan = write_plan(tmp_path)
    out, real = tmp_path / "s.nc", tmp_path / "elsewhere.journal"
    args = ("scan", str(plan), "-o", str(out), "--simulate", str(fine_field))
    assert raysim_main(*args, "--journal", str(real)).code == 0
    out.unlink()
    before = real.read_bytes()
    code, _, err = raysim_main(*args, "--resume")
    assert code == 2 and not out.exists() and not Path(f"{out}.journal").exists()
    assert error_line(err) == (f"error: no journal to resume at {out}.journal; run without --resume "
                               "to start the scan")
    assert real.read_bytes() == before
    header = before.splitlines(keepends=True)[0]
    Path(f"{out}.journal").write_bytes(header)
    assert raysim_main(*args, "--resume").code == 2
    assert raysim_main(*args, "--journal", str(real), "--resume").code == 0 and out.exists()


@pytest.mark.parametrize(("args", "message"), [
    (["--resource", "scope=TCPIP::1.2.3.4::5::SOCKET"], "write ROLE=VISA"),
    (["--simulate", "missing.nc"], "missing.nc: no such file"),
    (["--noise-db", "-1", "--simulate", "x.nc"], "noise_db (--noise-db, [simulator] noise_db) must be a number in 0..10"),
    (["--centre-offset", "0,0", "--simulate", "x.nc"], "three numbers X,Y,Z"),
])
def test_bad_options(tmp_path: Path, raysim_main, args: list[str], message: str) -> None:
    plan_path = write_plan(tmp_path)
    code, _, err = raysim_main("scan", str(plan_path), "-o", str(tmp_path / "s.nc"), *args)
    assert code == 2
    assert message in error_line(err)


def test_bad_plan_and_existing_journal(tmp_path: Path, raysim_main, fine_field: Path) -> None:
    plan_path = write_plan(tmp_path)
    bad = tmp_path / "bad.toml"
    bad.write_text(plan_path.read_text().replace("theta_step_deg = 20.0", "theta_step_deg = 0"))
    code, _, err = raysim_main("scan", str(bad), "-o", str(tmp_path / "s.nc"), "--simulate",
                               str(fine_field))
    assert code == 2
    assert "'grid.theta_step_deg' must be > 0" in error_line(err)
    out = tmp_path / "s.nc"
    code, _, err = raysim_main("scan", str(plan_path), "-o", str(out), "--simulate",
                               str(fine_field))
    assert code == 0, err
    journal = Path(str(out) + ".journal").read_bytes()
    code, _, err = raysim_main("scan", str(plan_path), "-o", str(out), "--simulate",
                               str(fine_field))
    assert code == 2
    assert "pass --resume" in error_line(err)
    assert Path(str(out) + ".journal").read_bytes() == journal


@pytest.mark.slow
def test_rig_park(tmp_path: Path, raysim_main) -> None:
    done = run_cli("rig", "park", str(ROOT / "scenes" / "rig.toml"), "--simulate")
    assert done.returncode == 0, done.stderr
    assert "parked: slider 95.0000 deg, rotation 0.0000 deg" in done.stdout
    code, _, err = raysim_main("rig", "park", str(ROOT / "scenes" / "rig.toml"),
                               f"--resource=motion=TCPIP::127.0.0.1::{closed_port()}::SOCKET")
    assert code == 2
    assert "motion controller at" in error_line(err) and "unreachable" in err


def _edit_journal(journal: Path, line: int, power: object) -> None:
    """Line ``line`` (1: the header) given the readings ``power``, with a valid CRC, as a
    hand-edited or foreign journal would hold them."""
    import json

    from hardware.journal import _with_crc

    lines = journal.read_bytes().splitlines(keepends=True)
    body = json.loads(lines[line - 1])
    del body["crc"]
    body["power"] = power
    lines[line - 1] = _with_crc(body)
    journal.write_bytes(b"".join(lines))


@pytest.mark.parametrize(("line", "power", "message"), [
    (2, [0.0, 0.0], "holds the power reading 0.0, not a finite power > 0 W"),  # the first reference
    (4, [], "holds no power reading"),
    (4, [1e-6, "abc"], 'holds the power reading "abc", not a finite power > 0 W'),
    (4, [1e-6, -1e-6], "holds the power reading -1e-06"),
    (4, [1e-6], "holds 1 power readings, the plan takes 2"),
])
def test_from_journal_refuses_readings_no_meter_gives(tmp_path: Path, raysim_main, line, power, message):
    """A journal's readings are checked by --from-journal: one line naming the journal line,
    exit 2, no FieldMap (a 0 W reference made every intensity 0, an empty list a NaN cell
    counted as measured, a string a traceback)."""
    import math

    from hardware.session import scan
    from raysim.maps.sphere import SphereGrid

    from .conftest import R, write_field

    plan = write_plan(tmp_path)  # 3 x 6 cells of 20 x 60 deg, 2 readings a step
    field = write_field(tmp_path / "field.nc", SphereGrid(R, 3, 6, 0.0, math.radians(60.0), 0.0, 2 * math.pi))
    scan(load_plan(plan), tmp_path / "scan.nc", simulate=field)
    journal = tmp_path / "scan.nc.journal"
    # the step's line in the file: the session line (hardware.journal) comes before step 0
    step, line = line - 2, line + 1
    _edit_journal(journal, line, power)
    out = tmp_path / "again.nc"
    code, _, err = raysim_main("scan", str(plan), "-o", str(out), "--journal", str(journal), "--from-journal")
    assert code == 2
    said = error_line(err)
    assert f"{journal}: line {line} (step {step})" in said and message in said
    assert not out.exists()


def test_from_journal_is_refused_while_a_scan_writes_the_journal(tmp_path: Path, raysim_main,
                                                                 fine_field: Path) -> None:
    """QA: --from-journal run while a scan wrote d.nc's journal ignored the journal's lock and
    wrote the live scan's output: a partial FieldMap over the finished file. It is refused in
    one line while the lock is held, the file left as it was, and works once the scan ends."""
    from hardware.journal import Journal

    plan = write_plan(tmp_path)
    out = tmp_path / "d.nc"
    assert raysim_main("scan", str(plan), "-o", str(out), "--simulate", str(fine_field)).code == 0
    before = out.read_bytes()
    journal = Path(f"{out}.journal")
    header = read_journal(journal)[0]
    with Journal.resume(journal, header["fingerprint"], header["steps"]):  # a scan at work
        code, _, err = raysim_main("scan", str(plan), "-o", str(out), "--from-journal")
        assert code == 2 and out.read_bytes() == before
        assert error_line(err) == f"error: {journal}: a scan is writing this journal; wait for it to end " \
            "(its FieldMap is written when it does)"
    assert raysim_main("scan", str(plan), "-o", str(out), "--from-journal").code == 0
