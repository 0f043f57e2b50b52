"""SIGINT (Ctrl-C to the process group) and SIGTERM end a command with one line and exit
status 130 / 143: no traceback from the client or from its Dask workers, and the run resumes."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from raysim.cli import interrupted_line
from tests.cli import popen_cli, run_cli
from tests.processes import kill_group, wait_until

pytestmark = pytest.mark.slow

# a 10 m dish at 1 GHz on a 30 x 80 sphere: 38 blocks of 64 points, about 0.2 s of work each
SCENE = """
name = "interrupted"
method = "po"
[dish]
diameter_m = 10.0
focal_length_m = 4.0
resolution_m = 0.2
[source]
frequency_hz = 1.0e9
[sphere]
radius_m = 2.0
n_theta = 30
n_phi = 80
"""


@pytest.mark.parametrize(("args", "terminated", "line"), [
    (["simulate", "s.toml", "-o", "o.nc", "--workers", "2"], False,
     "interrupted: raysim simulate stopped; resume with --resume"),
    (["simulate", "s.toml", "-o", "o.nc"], True, "interrupted: raysim simulate stopped by SIGTERM"),
    (["dataset", "d.toml", "-o", "d.zarr"], True,
     "interrupted: raysim dataset stopped by SIGTERM; resume with --resume"),
    (["report", "f.nc", "-o", "out"], False, "interrupted: raysim report stopped"),
])
def test_the_line_says_how_to_resume_only_where_resuming_exists(args, terminated, line):
    assert interrupted_line(args, terminated) == line


def test_a_command_adds_what_it_knows_to_the_line():
    assert interrupted_line(["scan", "plan.toml", "-o", "o.nc"], True, ["3 of 9 steps are in o.journal"]) == \
        "interrupted: raysim scan stopped by SIGTERM (3 of 9 steps are in o.journal); resume with --resume"


@pytest.mark.parametrize(("sig", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_to_the_group_ends_simulate_on_workers_with_one_line(tmp_path, sig, status):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    out = tmp_path / "o.nc"
    args = ["simulate", scene, "-o", out, "--workers", "2", "--block-size", "64"]
    proc = popen_cli(*args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    blocks = Path(f"{out}.partial.zarr") / "blocks"
    try:
        wait_until(lambda: proc.poll() is not None or (blocks.is_dir() and any(blocks.iterdir())),
                   240, "the first block")
        assert proc.poll() is None, "the run ended before it could be interrupted"
        time.sleep(0.5)
        os.killpg(proc.pid, sig)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        kill_group(proc)
    assert proc.returncode == status
    assert stdout == b""
    assert stderr.decode().splitlines() == [interrupted_line([str(a) for a in args], sig == signal.SIGTERM)]
    if sig == signal.SIGINT:  # the blocks kept are verified and the run completes
        done = run_cli(*args, "--resume", timeout=300)
        assert done.code == 0, done.stderr
        assert out.is_file() and not blocks.parent.exists()


def test_simulate_killed_then_corrupted_resumes_to_the_single_process_fieldmap(tmp_path):
    """SIGKILL to the whole run after a few blocks, then one block's chunks removed and
    another's truncated: --resume recomputes both (and says so), and the FieldMap is the
    single-process one bit for bit."""
    from raysim.maps.fieldmap import load
    from tests.raysim.distributed.conftest import assert_same_fieldmap

    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    out, single = tmp_path / "o.nc", tmp_path / "single.nc"
    args = ["simulate", scene, "-o", out, "--workers", "2", "--block-size", "64"]
    proc = popen_cli(*args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    store = Path(f"{out}.partial.zarr")
    try:
        wait_until(lambda: proc.poll() is not None or ((store / "blocks").is_dir()
                   and len(list((store / "blocks").glob("*.json"))) >= 3), 240, "three blocks")
        assert proc.poll() is None, "the run ended before it could be killed"
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        kill_group(proc)
    done = sorted(int(p.stem) for p in (store / "blocks").glob("*.json"))
    chunks = {i: [f for part in store.iterdir() if (part / "zarr.json").is_file()
                  for f in sorted((part / "c" / str(i)).rglob("*")) if f.is_file()] for i in done[:2]}
    for f in chunks[done[0]]:
        f.unlink()
    for f in chunks[done[1]]:
        f.write_bytes(f.read_bytes()[:10])
    resumed = run_cli(*args, "--resume", timeout=300)
    assert resumed.code == 0, resumed.stderr
    assert "2 failed verification and were recomputed" in resumed.stdout
    assert run_cli("simulate", scene, "-o", single, timeout=300).code == 0
    assert_same_fieldmap(load(single), load(out))


@pytest.mark.parametrize("to_the_group", [True, False])
def test_ctrl_c_during_a_dataset_is_one_line_and_the_store_resumes(tmp_path, to_the_group):
    """SIGINT once samples are done, to the group (client and its two local workers: Ctrl-C) or
    to the client alone (``kill -INT``): one line, status 130, no worker traceback (the workers
    outlived the scheduler and logged its absence); --resume completes the store."""
    demo = Path(__file__).resolve().parents[2] / "scenes" / "dataset_demo.toml"
    spec = tmp_path / "spec.toml"
    spec.write_text(demo.read_text().replace("samples = 8", "samples = 30"))
    store = tmp_path / "d.zarr"
    args = ["dataset", spec, "-o", store, "--workers", "2"]
    proc = popen_cli(*args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    status = store / "status" / "c"
    try:
        wait_until(lambda: proc.poll() is not None or (status.is_dir() and any(status.iterdir())), 240,
                   "the first sample")
        assert proc.poll() is None, "the run ended before it could be interrupted"
        (os.killpg if to_the_group else os.kill)(proc.pid, signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        kill_group(proc)
    assert proc.returncode == 130 and stdout == b""
    assert stderr.decode().splitlines() == ["interrupted: raysim dataset stopped; resume with --resume"]
    done = run_cli(*args, "--resume", timeout=300)
    assert done.code == 0, done.stderr
    assert "30/30 samples done" in done.stdout


def test_report_killed_or_terminated_leaves_no_staging_folder(tmp_path):
    """SIGKILL mid-report leaves its staging folder .out.XXXX.tmp (nothing can catch it); the
    next run removes it, and a SIGTERM ends that run with one line, status 143 and its own
    staging removed; a last run writes the report."""
    import numpy as np

    from raysim.maps.fieldmap import fieldmap, save
    from raysim.maps.sphere import SphereGrid, ideal_go_intensity

    grid = SphereGrid(3.0, 45, 180)
    t, p = np.meshgrid(grid.theta, grid.phi, indexing="ij")
    ideal = ideal_go_intensity(t, 8.0, 3.0, 20.0)
    field = tmp_path / "f.nc"
    save(fieldmap(grid, ideal * (1 + 0.01 * np.cos(2 * p)), ideal, focal_length=8.0, diameter=20.0,
                  frequency_hz=1e9, method="go", sampling="cell_mean"), field)
    args = ["report", field, "-o", tmp_path / "out"]

    def staged() -> set[Path]:
        return set(tmp_path.glob(".out.*"))

    def stop_once_staged(sig: int) -> tuple[int, str]:
        """Start the report, send ``sig`` once a staging folder of its own exists."""
        stale = staged()
        proc = popen_cli(*args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
        try:
            wait_until(lambda: proc.poll() is not None or bool(staged() - stale), 120, "the staging folder")
            assert proc.poll() is None, "the report was written before it could be stopped"
            proc.send_signal(sig)
            _, stderr = proc.communicate(timeout=60)
        finally:
            kill_group(proc)
        return proc.returncode, stderr.decode()

    code, _ = stop_once_staged(signal.SIGKILL)
    assert code == -signal.SIGKILL and len(staged()) == 1  # left behind: the next run's to remove
    code, stderr = stop_once_staged(signal.SIGTERM)
    assert code == 143 and "Traceback" not in stderr
    assert stderr.splitlines()[-1] == "interrupted: raysim report stopped by SIGTERM"
    assert staged() == set()
    done = run_cli(*args, timeout=300)
    assert done.code == 0, done.stderr
    assert (tmp_path / "out" / "report.html").is_file() and staged() == set()


@pytest.mark.parametrize(("sig", "status", "line"), [
    (signal.SIGINT, 130, "interrupted: raysim simulate stopped"),
    (signal.SIGTERM, 143, "interrupted: raysim simulate stopped by SIGTERM")])
def test_a_signal_while_the_command_loads_is_the_one_line(sig, status, line):
    """In the second the console script spends importing its modules, Ctrl-C printed a
    KeyboardInterrupt traceback and SIGTERM ended it without a word. The signal is sent at a
    fixed point here: after the early handlers, before the command's modules load."""
    import sys

    from tests.cli import ROOT, cli_env

    script = ("import os, signal, sys, time\n"
              "sys.argv = ['raysim', 'simulate', 'paper_go', '-o', 'x.nc']\n"
              "from raysim.console import install_early_handlers\n"
              "install_early_handlers()\n"
              f"os.kill(os.getpid(), {int(sig)})\n"
              "import raysim.cli\n"
              "time.sleep(30)\n")
    done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=cli_env(),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == status
    assert done.stderr == line + "\n"


_SIGNAL_IN_THE_START = '''
import os, signal, sys, time

def run(when, sig):
    import distributed
    start = distributed.LocalCluster.__init__

    def init(self, *args, **kwargs):  # the signal to the whole group at a fixed point
        if when == "before the workers":
            os.killpg(0, sig)
        start(self, *args, **kwargs)
        if when == "with the workers up":
            os.killpg(0, sig)
            time.sleep(1.0)  # a worker that took the signal prints its traceback meanwhile

    distributed.LocalCluster.__init__ = init
    sys.argv = ["raysim", "simulate", "s.toml", "-o", "o.nc", "--workers", "2"]
    from raysim.console import main
    main()

if __name__ == "__main__":  # worker processes import this file again
    run(sys.argv[1], int(sys.argv[2]))
'''


@pytest.mark.parametrize("when", ["before the workers", "with the workers up"])
@pytest.mark.parametrize(("sig", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_while_the_local_cluster_starts_is_the_one_line(tmp_path, when, sig, status):
    """While a local cluster started, SIGINT was ignored in the client (so that its workers
    inherited the ignoring) and the run went on to exit 0; SIGTERM left a half-made cluster to
    Dask's exit hook, which printed a traceback. The signal goes to the process group, as
    Ctrl-C does, at a fixed point of the start."""
    import sys

    from tests.cli import cli_env

    (tmp_path / "s.toml").write_text(SCENE)
    (tmp_path / "start.py").write_text(_SIGNAL_IN_THE_START)
    done = subprocess.run([sys.executable, "start.py", when, str(int(sig))], cwd=tmp_path,
                          env=cli_env(), capture_output=True, text=True, timeout=120,
                          start_new_session=True)
    assert done.returncode == status, done.stderr
    assert done.stderr.splitlines() == [interrupted_line(
        ["simulate", "s.toml", "-o", "o.nc", "--workers", "2"], sig == signal.SIGTERM)]
    assert not (tmp_path / "o.nc").exists()
