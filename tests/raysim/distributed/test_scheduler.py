"""A separately started `dask scheduler` and two `dask worker` processes on loopback, the CLI as
client, PO on a small dish: the single-process FieldMap bit for bit; a worker killed mid-run;
the client killed mid-run and the run resumed with --resume; no block computed twice."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from raysim.distributed.partial import partial_path
from raysim.maps.fieldmap import load
from raysim.scene.scene import load_scene
from raysim.simulate import simulate
from tests.cli import cli_env
from tests.processes import dask_processes, wait_until, worker_processes
from tests.raysim.distributed.conftest import SMALL, assert_same_fieldmap

pytestmark = pytest.mark.slow

# the small dish at 2.5 GHz on 18 x 48 points: ~50 000 PO samples per reflector, 54 blocks of
# 16 points (a few hundredths of a second each on one idle core), long enough to kill mid-run
SCENE = SMALL.replace("frequency_hz = 1.0e9", "frequency_hz = 2.5e9").replace(
    "n_theta = 9", "n_theta = 18").replace("n_phi = 36", "n_phi = 48")
BLOCK = 16
N_BLOCKS = -(-18 * 48 // BLOCK)
RUN_TIMEOUT = 300  # s


def _markers(output: Path) -> int:
    folder = partial_path(output) / "blocks"
    return len(list(folder.glob("*.json"))) if folder.is_dir() else 0


def _simulate(scene: Path, output: Path, address: str, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "raysim.cli", "simulate", str(scene), "-o", str(output),
                             "--method", "po", "--scheduler", address, "--block-size", str(BLOCK), *extra],
                            env=cli_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _finish(run: subprocess.Popen) -> tuple[str, str]:
    try:
        out, err = run.communicate(timeout=RUN_TIMEOUT)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait(timeout=15)
    assert run.returncode == 0, err
    return out, err


def _settled(output: Path, quiet: float = 3.0) -> None:
    """Wait until no block marker has appeared for ``quiet`` seconds (the workers are idle)."""
    last, since = _markers(output), time.monotonic()
    while time.monotonic() - since < quiet:
        time.sleep(0.2)
        now = _markers(output)
        if now != last:
            last, since = now, time.monotonic()


def test_scheduler_and_two_workers_with_a_worker_and_the_client_killed(tmp_path):
    scene_path = tmp_path / "small.toml"
    scene_path.write_text(SCENE)
    reference = simulate(load_scene(scene_path), "po")  # the same file: the same scene_folder
    with dask_processes(2) as (address, nanny_pid):
        # 1. a worker process killed after a few blocks: its nanny restarts it, the run completes
        first = tmp_path / "first.nc"
        run = _simulate(scene_path, first, address)
        wait_until(lambda: _markers(first) >= 3 or run.poll() is not None, RUN_TIMEOUT, "three blocks")
        killed = run.poll() is None and _markers(first) < N_BLOCKS
        with contextlib.suppress(ProcessLookupError):
            os.kill(worker_processes(nanny_pid)[0], signal.SIGKILL)
        out, _ = _finish(run)
        assert killed, "the run ended before a worker could be killed"
        ds = load(first)
        assert_same_fieldmap(reference, ds)
        assert (ds.attrs["blocks"], ds.attrs["blocks_computed_twice"]) == (N_BLOCKS, 0)
        assert f"{N_BLOCKS} blocks on 2 workers" in out and "0 computed twice" in out
        assert not partial_path(first).exists()

        # 2. the client killed after a few blocks: the partial store stays; --resume completes it
        second = tmp_path / "second.nc"
        run = _simulate(scene_path, second, address)
        wait_until(lambda: _markers(second) >= 3 or run.poll() is not None, RUN_TIMEOUT, "three blocks")
        run.send_signal(signal.SIGKILL)
        run.wait(timeout=15)
        _settled(second)  # blocks in flight when the client died finish and are kept
        kept = _markers(second)
        assert 3 <= kept < N_BLOCKS and not second.exists()
        out, _ = _finish(_simulate(scene_path, second, address, "--resume"))
        ds = load(second)
        assert_same_fieldmap(reference, ds)
        a = ds.attrs
        assert (a["blocks_reused"], a["blocks_computed"], a["blocks_computed_twice"]) == \
            (kept, N_BLOCKS - kept, 0)
        assert f"{kept} reused, 0 computed twice" in out
