"""Files at the edge: the example inputs shipped with raysim, and the guard on outputs.

- The examples (scenes, scan plans, the rig file, dataset specs) live in the repository's
  ``scenes/`` folder and ship in the wheel as ``raysim/examples/``. Wherever a file is
  accepted, a name that is not an existing path is looked up among them (``paper_go`` or
  ``paper_go.toml``); a path that exists always wins.
- :func:`check_output` refuses an output that is one of the command's inputs (after
  resolving symbolic links and relative paths), before any work is done.
- :func:`new_file_mode` is the mode a new file gets under the process's umask (0644 under
  022), for files written through a private temporary file.
- :func:`atomic_path` is the one way an output file is written: into a temporary file beside
  it (``.NAME.XXXX.tmp``), flushed, then renamed over it, so that ``NAME`` is either the
  previous file or the complete new one (a full disk, a kill, an interrupt leave the
  previous state); :func:`write_bytes` and :func:`write_text` use it.
  :func:`remove_stale` removes the temporary files and staging folders an earlier killed run
  left beside an output.

A leaf module: it imports nothing of raysim but the error base class.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import stat
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path

from raysim.errors import RaysimError

EXAMPLE_SUFFIXES = (".toml",)


def examples_dir() -> Path:
    """The folder of the shipped examples: ``raysim/examples`` in a wheel, ``scenes/`` in a
    checkout."""
    package = Path(__file__).resolve().parent
    installed = package / "examples"
    if installed.is_dir():
        return installed
    return package.parent / "scenes"


def example_names() -> list[str]:
    """The names of the shipped examples (file names without ``.toml``), sorted."""
    folder = examples_dir()
    if not folder.is_dir():
        return []
    return sorted(p.stem for p in folder.iterdir() if p.suffix in EXAMPLE_SUFFIXES and p.is_file())


def example(name: str) -> Path | None:
    """The shipped example called ``name`` (with or without ``.toml``), or None."""
    if not name or "/" in name or os.sep in name or name.startswith("."):
        return None
    folder = examples_dir()
    for candidate in (folder / name, folder / f"{name}.toml"):
        if candidate.suffix in EXAMPLE_SUFFIXES and candidate.is_file():
            return candidate
    return None


def example_summary(path: Path) -> tuple[str, str]:
    """(kind, one-line description) of an example file: scene, dataset spec, scan plan or rig,
    described by its ``description`` key or else its first comment line."""
    import tomllib

    text = path.read_text(encoding="utf-8")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        data = {}
    if "samples" in data:
        kind = "dataset spec"
    elif "reflector" in data and "grid" in data:
        kind = "scan plan"
    elif "track" in data:
        kind = "rig file"
    else:
        kind = "scene"
    description = data.get("description")
    if not isinstance(description, str) or not description.strip():
        comments = [line.lstrip("#").strip() for line in text.splitlines() if line.startswith("#")]
        description = comments[0] if comments else ""
    return kind, " ".join(description.split())


def example_references(path: Path) -> list[str]:
    """The files an example names beside itself (a plan's ``rig``, a spec's ``scene``)."""
    import tomllib

    data = tomllib.loads(path.read_text(encoding="utf-8"))
    refs = [data[key] for key in ("rig", "scene") if isinstance(data.get(key), str)]
    return [r for r in refs if not Path(r).is_absolute()]


def copy_example(name: str, folder: str | os.PathLike[str]) -> list[Path]:
    """Copy the example ``name`` and the files it names into ``folder`` (created if needed);
    return the written paths. An existing file is never overwritten."""
    source = example(name)
    if source is None:
        known = ", ".join(example_names())
        raise RaysimError(f"no example called {name!r} (known: {known})")
    target = Path(folder).expanduser()
    if target.exists() and not target.is_dir():
        raise RaysimError(f"{target}: exists and is not a folder")
    files = [source, *(source.parent / ref for ref in example_references(source))]
    files = [f for f in files if f.is_file()]
    for f in files:
        if (target / f.name).exists():
            raise RaysimError(f"{target / f.name}: exists; not overwritten (copy into another folder)")
    target.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    try:
        for f in files:
            dest = target / f.name
            write_text(dest, f.read_text(encoding="utf-8"))
            written.append(dest)
    except BaseException:  # all or nothing: a full disk leaves the folder as it was
        for dest in written:
            dest.unlink(missing_ok=True)
        raise
    return written


def find_input(path: str | os.PathLike[str], base: Path | None = None) -> Path:
    """The file a user means by ``path``: the path itself when it exists, else the shipped
    example of that name, else the path unchanged (so the caller's "no such file" names what
    the user wrote).

    ``base`` is the folder of the file that holds a reference (a plan's ``rig = "rig.toml"``):
    the reference resolves beside that file, and only a bare name without a suffix
    (``rig = "rig"``) may fall back to an example, so that a missing file beside a plan is an
    error and never silently the example's."""
    given = Path(path).expanduser()
    candidate = given if base is None or given.is_absolute() else base / given
    if candidate.exists():
        return candidate
    if base is not None and given.suffix:
        return candidate
    shipped = example(str(path))
    return shipped if shipped is not None else candidate


def same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    """Whether two paths name one file (symbolic links and relative paths resolved; a path
    that does not exist yet compares by its resolved name)."""
    pa, pb = Path(a).expanduser(), Path(b).expanduser()
    try:
        if pa.exists() and pb.exists():
            return os.path.samefile(pa, pb)
    except OSError:
        pass
    return pa.resolve() == pb.resolve()


def check_output(output: str | os.PathLike[str],
                 inputs: Iterable[tuple[str, str | os.PathLike[str] | None]],
                 error: type[RaysimError] = RaysimError) -> None:
    """Refuse ``output`` when it is one of ``inputs`` ((what, path) pairs; None skipped)."""
    for what, path in inputs:
        if path is None or "://" in str(path):
            continue
        if same_file(output, path):
            raise error(f"{output}: is the {what} ({path}); writing it would destroy the input, "
                        "give another output path")


def check_output_folder(folder: str | os.PathLike[str],
                        inputs: Iterable[tuple[str, str | os.PathLike[str] | None]],
                        error: type[RaysimError] = RaysimError) -> None:
    """Refuse an output ``folder`` that would be replaced while an input lies inside it (or is
    the folder itself)."""
    target = Path(folder).expanduser().resolve()
    for what, path in inputs:
        if path is None:
            continue
        resolved = Path(path).expanduser().resolve()
        if resolved == target or target in resolved.parents:
            raise error(f"{folder}: holds the {what} ({path}); replacing the folder would destroy "
                        "the input, give another output folder")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def new_file_mode() -> int:
    """Permission bits a newly created file gets under the current umask (0o644 under 022)."""
    return 0o666 & ~_umask()


def new_folder_mode() -> int:
    """Permission bits a newly created folder gets under the current umask (0o755 under 022)."""
    return 0o777 & ~_umask()


#: how old (s) a leftover whose writer cannot be told (another host, an older raysim's name)
#: must be before it is taken for a killed run's
FOREIGN_STALE_S = 24 * 3600.0


def writer_prefix(path: str | os.PathLike[str]) -> str:
    """The name prefix of a temporary file or staging folder beside ``path`` (``.NAME.``),
    with the writer's host and process id, so that a later run removes only what a dead
    writer left (:func:`remove_stale`), never the work of one still running."""
    return f".{Path(path).name}.{socket.gethostname()}-{os.getpid()}-"


def _writer_alive(stale: Path, name: str) -> bool:
    """Whether the writer that made ``stale`` (beside a file called ``name``) may still run:
    a process of this host that exists, or, where the name does not tell (another host, an
    older name), anything younger than :data:`FOREIGN_STALE_S`."""
    rest = stale.name[len(name) + 2:]
    if rest.startswith("old-"):
        host, pid = socket.gethostname(), rest[4:]
    else:
        host = rest.rpartition("-")[0]  # host-pid-RANDOM.tmp: mkstemp's RANDOM has no "-"
        host, _, pid = host.rpartition("-")
    if host == socket.gethostname() and pid.isdigit():
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True  # another user's live process
        return True
    try:
        return time.time() - stale.lstat().st_mtime < FOREIGN_STALE_S
    except OSError:
        return False


def remove_stale(path: str | os.PathLike[str]) -> None:
    """Remove what killed writers of ``path`` left beside it: temporary files and staging
    folders ``.NAME.*.tmp`` and replaced folders ``.NAME.old-PID``, each only when the run
    that made it is no longer alive (two runs on one output never delete each other's work).
    A replaced folder whose writer was killed before its new one took its place is put back
    as ``path`` when ``path`` is missing: it is the user's previous output."""
    path = Path(path)
    if not path.parent.is_dir():
        return
    for pattern in (f".{path.name}.old-*", f".{path.name}.*.tmp"):
        for stale in sorted(path.parent.glob(pattern)):
            if _writer_alive(stale, path.name):
                continue
            if pattern.endswith("old-*") and not os.path.lexists(path):
                with contextlib.suppress(OSError):  # if it cannot go back, it stays as it is
                    os.replace(stale, path)
                continue
            if stale.is_dir() and not stale.is_symlink():
                shutil.rmtree(stale, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    stale.unlink()


def folder_state(folder: str | os.PathLike[str]) -> dict[str, tuple[int, ...]]:
    """What ``folder`` holds, to tell later whether anything was added or changed in it:
    each entry's path relative to it, with (kind, inode, size, mtime in ns); empty for a
    missing folder. A symbolic link counts as itself (it is not followed)."""
    root = Path(folder)
    state: dict[str, tuple[int, ...]] = {}
    if not root.is_dir():
        return state
    for dirpath, dirnames, filenames in os.walk(root):
        for name in (*dirnames, *filenames):
            entry = Path(dirpath) / name
            try:
                st = entry.lstat()
            except OSError:  # gone meanwhile: not there
                continue
            state[str(entry.relative_to(root))] = (st.st_mode >> 12, st.st_ino, st.st_size,
                                                   st.st_mtime_ns)
    return state


def changed_since(folder: str | os.PathLike[str], before: dict[str, tuple[int, ...]]) -> list[str]:
    """The entries of ``folder`` added or changed since :func:`folder_state` gave ``before``
    (relative paths, sorted); a folder's own time changes with what it holds, so folders count
    only as new ones."""
    now = folder_state(folder)
    return sorted(name for name, sig in now.items()
                  if name not in before or (sig[0] != stat.S_IFDIR >> 12 and before[name] != sig))


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], clean: bool = True) -> Iterator[Path]:
    """A temporary file beside ``path`` to write; when the block completes it is flushed to
    disk and renamed onto ``path`` (with the mode a new file gets), else removed.

    ``path`` is never seen half-written: a full disk, a kill or an interrupt leave the
    previous file (or none). An OSError (ENOSPC, EDQUOT, ...) is raised again naming
    ``path``, which the CLI prints as one line. ``clean``: first remove what killed writers
    left beside it (:func:`remove_stale`).
    """
    path = Path(path)
    tmp = _stage(path, clean)
    try:
        yield tmp
        _flush(tmp)
        _commit(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_together(writers: Mapping[str | os.PathLike[str], Callable[[Path], object]]) -> list[Path]:
    """Write several files as one set: each ``writers[path](tmp)`` writes a temporary file
    beside its ``path``; only when every one is written and flushed are they renamed onto
    their paths, with SIGINT and SIGTERM held back meanwhile (raised once the set is in
    place). A failure, a full disk or an interrupt leaves the previous files, all of them; only
    a kill between two renames (microseconds) could mix the sets. Returns the paths."""
    staged: list[tuple[Path, Path]] = []
    try:
        for path, write in writers.items():
            path = Path(path)
            staged.append((_stage(path, clean=True), path))
            try:
                write(staged[-1][0])
                _flush(staged[-1][0])
            except OSError as exc:
                raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
        with _signals_held():
            for tmp, path in staged:
                try:
                    _commit(tmp, path)
                except OSError as exc:
                    raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
    finally:
        for tmp, _ in staged:
            tmp.unlink(missing_ok=True)  # none left after the renames; all of them after a failure
    return [path for _, path in staged]


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """SIGINT and SIGTERM recorded while the block runs and raised again after it, to the
    handlers that were there. (A signal mask would not do: the kernel hands a process's
    signal to any thread that does not block it, and Python then runs its handler in the main
    thread at once.) Outside the main thread, where handlers cannot be set, nothing is held."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    held = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.signal(s, lambda signum, frame: pending.append(signum)) for s in held}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        for s in dict.fromkeys(pending):
            signal.raise_signal(s)


def _stage(path: Path, clean: bool) -> Path:
    """A new empty temporary file beside ``path`` named for this writer (its folder made)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if clean:
        remove_stale(path)
    try:
        fd, name = tempfile.mkstemp(prefix=writer_prefix(path), suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
    os.close(fd)
    return Path(name)


def _flush(tmp: Path) -> None:
    """Give ``tmp`` a new file's mode and sync its contents to disk."""
    os.chmod(tmp, new_file_mode())
    with open(tmp, "rb+") as fh:
        os.fsync(fh.fileno())


def _commit(tmp: Path, path: Path) -> None:
    """Rename ``tmp`` onto ``path`` and sync the rename itself where the file system allows."""
    os.replace(tmp, path)
    with contextlib.suppress(OSError):
        dir_fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)


def probe_writable(folder: str | os.PathLike[str]) -> None:
    """OSError unless a new entry can be made in ``folder``: a real probe (a folder made and
    removed), since permissions alone do not tell (root, read-only mounts, /proc)."""
    tempfile.TemporaryDirectory(dir=folder, prefix=".raysim-probe-").cleanup()


def write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` through :func:`atomic_path`; return the path."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through :func:`atomic_path`; return the path."""
    return write_bytes(path, text.encode("utf-8"))
