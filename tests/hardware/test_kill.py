"""Kill tests: ``raysim scan`` killed at random moments and resumed gives the uninterrupted map.

The scans run as real subprocesses against the simulated rig (noise and drift on, so equal
arrays mean every sample was taken at its own index exactly once); they are killed with SIGINT,
SIGTERM and SIGKILL at seeded random moments: after a random number of further journal
records plus a random delay, or early during start-up.
"""

from __future__ import annotations

import random
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from hardware.journal import read_journal
from hardware.plan import load_plan
from hardware.session import scan
from raysim.maps import fieldmap as fieldmaps
from tests.cli import popen_cli

from .conftest import run_cli, write_plan


def journal_lines(path: Path) -> int:
    """Complete lines in the journal, header excluded (0 while it does not exist)."""
    try:
        return max(path.read_bytes().count(b"\n") - 1, 0)
    except FileNotFoundError:
        return 0


def kill_once(args: list[str], journal: Path, sig: int, rng: random.Random,
              early: bool) -> tuple[int, str]:
    """Start the scan, kill it with ``sig`` at a random moment; (exit status, stderr)."""
    proc = popen_cli(*args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        if early:
            time.sleep(rng.uniform(0.05, 0.6))
        else:
            target = journal_lines(journal) + rng.randint(3, 20)
            deadline = time.monotonic() + 30.0
            while journal_lines(journal) < target and proc.poll() is None:
                assert time.monotonic() < deadline, "the scan made no progress"
                time.sleep(0.002)
            time.sleep(rng.uniform(0.0, 0.02))
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, err


@pytest.mark.slow
def test_killed_and_resumed_scan_equals_uninterrupted(tmp_path: Path, fine_field: Path) -> None:
    plan_path = write_plan(tmp_path, theta_max=80.0, theta_step=10.0, phi_step=30.0, samples=3,
                           every=3, noise=0.01, drift=0.05, time_scale=0.002)
    plan = load_plan(plan_path)
    total = len(plan.steps())
    whole = scan(plan, tmp_path / "whole.nc", simulate=fine_field).fieldmap

    out = tmp_path / "killed.nc"
    journal = Path(str(out) + ".journal")
    first = ["scan", str(plan_path), "-o", str(out), "--simulate", str(fine_field)]
    args = [*first, "--resume"]  # refused while no journal holds a step: the first run goes without
    rng = random.Random(20240611)
    kills = [(signal.SIGKILL, True), (signal.SIGINT, False), (signal.SIGTERM, False),
             (signal.SIGKILL, False), (signal.SIGKILL, False), (signal.SIGTERM, False),
             (signal.SIGKILL, False)]
    done_before = 0
    for sig, early in kills:
        held = journal.exists() and bool(read_journal(journal)[1])
        code, err = kill_once(args if held else first, journal, sig, rng, early)
        if code == 0 and done_before:
            break                             # finished before the signal came: still valid
        if code == 0:
            # finished before any kill landed mid-scan (a loaded machine can starve the
            # watcher): nothing was tested yet, so start the scan afresh for the next kill
            out.unlink()
            journal.unlink()
            continue
        if sig == signal.SIGKILL:
            assert code == -signal.SIGKILL
        else:
            assert code == (143 if sig == signal.SIGTERM else 130), err
            # the line offers --resume where a journal with steps was kept
            kept = journal.exists() and bool(read_journal(journal)[1])
            assert "interrupted:" in err and ("--resume" in err) == kept, err
        if journal.exists() and journal.stat().st_size:
            records = read_journal(journal)[1]     # intact: no gap, duplicate or reordering
            assert len(records) >= done_before
            done_before = len(records)
    assert 0 < done_before < total
    assert not out.exists()

    done = run_cli(*args)
    assert done.returncode == 0, done.stderr
    _, records, _ = read_journal(journal)
    assert [r.n for r in records] == list(range(total))
    resumed = fieldmaps.load(out)
    compared = 0
    for name in whole.data_vars:
        if name in ("time", "reference_time"):
            continue
        assert np.array_equal(whole[name].values, resumed[name].values, equal_nan=True), name
        compared += 1
    assert compared >= 15
    assert np.isfinite(resumed["intensity"].values).all()
