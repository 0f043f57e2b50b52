"""Outputs are written through a temporary file and a rename: a full disk (ENOSPC, simulated
by failing the write) leaves the previous state and one line; stale staging is removed."""

from __future__ import annotations

import errno
import os
import time
from pathlib import Path

import numpy as np
import pytest

from raysim.files import atomic_path, example, remove_stale
from raysim.maps.fieldmap import fieldmap, save
from raysim.maps.sphere import SphereGrid, ideal_go_intensity
from raysim.pipeline.report import staging
from tests.cli import run_in_process


def _disk_full(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def _listing(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_an_interrupted_write_leaves_the_previous_file_and_no_temporary(tmp_path):
    path = tmp_path / "out.bin"
    path.write_bytes(b"previous")
    with pytest.raises(OSError, match="No space left") as info, atomic_path(path) as tmp:
        tmp.write_bytes(b"half")
        _disk_full()
    assert info.value.filename == str(path)
    assert _listing(tmp_path) == {"out.bin": b"previous"}
    with atomic_path(path) as tmp:
        tmp.write_bytes(b"new")
    assert _listing(tmp_path) == {"out.bin": b"new"}


def test_a_set_of_files_is_replaced_whole_or_not_at_all(tmp_path, monkeypatch):
    """QA: `raysim correct` wrote its five files one by one, so a SIGTERM or a full disk
    midway left new commands beside the previous fit's residual and summary. A failure while
    writing the third file leaves the old set; a SIGTERM arriving between two renames is
    raised only once the whole new set is in place."""
    import signal

    from raysim import files

    names = ("a.csv", "b.toml", "c.nc")
    for name in names:
        (tmp_path / name).write_text("old " + name)
    old = _listing(tmp_path)

    def writers(third):
        return {tmp_path / n: (lambda p, n=n: p.write_text("new " + n)) for n in names[:2]} | {
            tmp_path / names[2]: third}

    def full(p):
        p.write_text("half")
        _disk_full()

    with pytest.raises(OSError, match="No space left") as info:
        files.write_together(writers(full))
    assert info.value.filename == str(tmp_path / "c.nc")
    assert _listing(tmp_path) == old  # no new file, no temporary

    class Stopped(Exception):
        pass

    def stop(signum, frame):
        raise Stopped

    commit = files._commit
    calls = []

    def commit_then_signal(tmp, path):
        commit(tmp, path)
        calls.append(path)
        if len(calls) == 1:
            os.kill(os.getpid(), signal.SIGTERM)

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        monkeypatch.setattr(files, "_commit", commit_then_signal)
        with pytest.raises(Stopped):
            files.write_together(writers(lambda p: p.write_text("new c.nc")))
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert _listing(tmp_path) == {n: ("new " + n).encode() for n in names}


def test_render_on_a_full_disk_keeps_the_previous_picture(tmp_path, capfd, monkeypatch):
    grid = SphereGrid(3.0, 10, 20)
    t, _ = np.meshgrid(grid.theta, grid.phi, indexing="ij")
    ideal = ideal_go_intensity(t, 8.0, 3.0, 20.0)
    save(fieldmap(grid, ideal * 1.001, ideal, focal_length=8.0, diameter=20.0, frequency_hz=1e9,
                  method="go", sampling="cell_mean"), tmp_path / "f.nc")
    assert run_in_process(capfd, "render", tmp_path / "f.nc", "-o", tmp_path / "o.png").code == 0
    before = _listing(tmp_path)

    import matplotlib.image

    def half_then_full(fname, *args, **kwargs):
        Path(fname).write_bytes(b"\x89PNG half")
        _disk_full()

    monkeypatch.setattr(matplotlib.image, "imsave", half_then_full)
    result = run_in_process(capfd, "render", tmp_path / "f.nc", "-o", tmp_path / "o.png")
    assert result.code == 2
    assert result.stderr.strip().splitlines() == [f"error: {tmp_path / 'o.png'}: No space left on device"]
    assert _listing(tmp_path) == before


def test_scenes_copy_on_a_full_disk_writes_nothing(tmp_path, capfd, monkeypatch):
    """scan_demo names its rig: the second file fails, the first is taken back."""
    assert example("scan_demo") is not None
    target = tmp_path / "copies"
    target.mkdir()
    real = Path.write_bytes
    calls = []

    def second_fails(self, data):
        calls.append(self)
        if len(calls) == 2:
            real(self, data[:3])
            _disk_full()
        return real(self, data)

    monkeypatch.setattr(Path, "write_bytes", second_fails)
    result = run_in_process(capfd, "scenes", "copy", "scan_demo", target)
    assert result.code == 2 and len(result.stderr.strip().splitlines()) == 1
    assert "No space left on device" in result.stderr
    assert list(target.iterdir()) == []


def test_a_later_run_removes_the_staging_a_killed_one_left(tmp_path):
    import socket
    import subprocess
    import sys

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    dead_pid = int(dead.stdout)  # a process that has ended
    host = socket.gethostname()
    target = tmp_path / "out"
    killed = tmp_path / f".out.{host}-{dead_pid}-k1ll.tmp"
    killed.mkdir()
    (killed / "report.html").write_text("half")
    (tmp_path / f".out.old-{dead_pid}").mkdir()
    (tmp_path / f".out.{host}-{dead_pid}-k2ll.tmp").write_text("half a file")
    live = tmp_path / f".out.{host}-{os.getpid()}-busy.tmp"  # a run still writing: kept
    live.mkdir()
    other_host = tmp_path / ".out.elsewhere-1-busy.tmp"  # another host's, young: kept
    other_host.mkdir()
    old_name = tmp_path / ".out.k3ll.tmp"  # an older raysim's name, a day old: removed
    old_name.mkdir()
    os.utime(old_name, (time.time() - 2 * 86400,) * 2)
    (tmp_path / ".other.k1ll.tmp").mkdir()  # another output's: kept
    with staging(target) as tmp:
        (tmp / "report.html").write_text("whole")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [".other.k1ll.tmp", "out", live.name, other_host.name])
    assert (target / "report.html").read_text() == "whole"
    remove_stale(tmp_path / "missing" / "x")  # no folder: nothing to do


def _dead_pid() -> int:
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    return int(done.stdout)  # a process that has ended


def test_an_interrupt_between_the_two_renames_puts_the_old_folder_back(tmp_path, monkeypatch):
    """Ctrl-C after the old report was moved aside and before the new one took its place
    left no report at all (found by killing runs at random)."""
    target = tmp_path / "out"
    target.mkdir()
    (target / "report.html").write_text("old")
    real = os.replace

    def interrupted(src, dst):
        real(src, dst)
        if Path(dst).name.startswith(".out.old-"):
            raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt), staging(target) as tmp:
        (tmp / "report.html").write_text("new")
    assert (target / "report.html").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_later_run_puts_back_the_folder_a_killed_one_had_moved_aside(tmp_path):
    """A kill between the two renames leaves only ``.out.old-PID``; the next run deleted it as
    garbage before writing anything. Now it is the output again, and replaced as usual."""
    pid = _dead_pid()
    aside = tmp_path / f".out.old-{pid}"
    aside.mkdir()
    (aside / "report.html").write_text("old")
    remove_stale(tmp_path / "out")
    assert (tmp_path / "out" / "report.html").read_text() == "old"
    assert not aside.exists()
    # with the output there, an orphaned copy is garbage as before
    aside.mkdir()
    remove_stale(tmp_path / "out")
    assert not aside.exists() and (tmp_path / "out" / "report.html").read_text() == "old"


def test_a_file_put_in_the_output_folder_during_the_run_is_kept(tmp_path):
    """A crew's notes.txt written into the (accepted, empty) folder while the run worked was
    deleted with the folder the result replaced, exit 0. Now the folder stays as it is, the
    result waits beside it in out.new, and one error line names both."""
    from raysim.render.backend import RenderError

    target = tmp_path / "out"
    target.mkdir()
    with pytest.raises(RenderError, match=r"out: notes.txt appeared in it during the run, so it "
                                          r"was not replaced; the result is in .*out\.new$"),\
            staging(target) as tmp:
        (tmp / "report.html").write_text("new")
        (target / "notes.txt").write_text("crew notes")
    assert (target / "notes.txt").read_text() == "crew notes"
    assert sorted(p.name for p in target.iterdir()) == ["notes.txt"]
    assert (tmp_path / "out.new" / "report.html").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "out.new"]
    # an earlier run's file edited meanwhile counts as well; the next result takes out.new-2
    (target / "report.html").write_text("old")
    with pytest.raises(RenderError, match=r"figures and 1 more appeared .*out\.new-2$"),\
            staging(target) as tmp:
        (tmp / "report.html").write_text("new")
        (target / "report.html").write_text("edited by hand")
        (target / "figures").mkdir()
    assert (target / "report.html").read_text() == "edited by hand"
    assert (tmp_path / "out.new-2" / "report.html").read_text() == "new"


def test_an_earlier_runs_files_left_alone_are_replaced(tmp_path):
    target = tmp_path / "out"
    (target / "figures").mkdir(parents=True)
    (target / "report.html").write_text("old")
    (target / "figures" / "a.png").write_text("old")
    with staging(target) as tmp:
        (tmp / "report.html").write_text("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert sorted(p.name for p in target.iterdir()) == ["report.html"]


def test_a_file_written_just_before_the_swap_is_kept(tmp_path, monkeypatch):
    """A file written after the last look and before the rename lands in the old folder: the
    look there finds it and the swap is undone (the old folder was deleted with it)."""
    import raysim.files
    from raysim.render.backend import RenderError

    target = tmp_path / "out"
    target.mkdir()
    real = raysim.files.changed_since
    looks = []

    def late(folder, before):
        found = real(folder, before)
        if not looks:  # the first look finds nothing, then the crew writes
            (target / "late.txt").write_text("late")
        looks.append(found)
        return found

    monkeypatch.setattr(raysim.files, "changed_since", late)
    with pytest.raises(RenderError, match=r"late.txt appeared"), staging(target) as tmp:
        (tmp / "report.html").write_text("new")
    assert looks[0] == [] and looks[1] == ["late.txt"]
    assert sorted(p.name for p in target.iterdir()) == ["late.txt"]
    assert (tmp_path / "out.new" / "report.html").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "out.new"]
