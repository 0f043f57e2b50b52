"""The scan journal: an append-only JSON Lines file, one record per completed step.

The first line is a header naming the plan's fingerprint and the number of steps; each later
line is one completed step (its index, kind, cell, commanded and read-back axes in rad, the
individual readings in W, the time in s since the epoch) with a CRC-32 of its content. A
record is written with one ``write`` and synced to disk (``fsync``) before the scan moves on.

Reading stops at the first line that is not a complete, intact record: a torn last line (a
kill during the write, so without its newline) is ignored and cut off before the journal is
appended to again; a bad record followed by good ones, or a last line complete with its newline
whose check fails, is corruption and an error. Records must carry the indices 0, 1,
2, ... in order, so a resumed scan continues after the last complete one with no duplicate,
no gap and no reordering.

Between records, a session line ``{"session": {...}}`` (with its CRC) says what the FieldMap
must say of the instruments that took the steps after it: whether the rig was simulated (and
the simulator's settings), the meter's identity, the controller's version. Each session that
opens the instruments writes one before its first step, so a journal alone (``--from-journal``,
a resume with no step left) gives the FieldMap the attributes of the scan that made it: a
rehearsal never reads as a real measurement. Version 2 has them; version 1 journals (without)
are still read and resumed.
"""

from __future__ import annotations

import fcntl
import json
import math
import os
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, NamedTuple

from hardware.errors import JournalError

FORMAT = "raysim-scan-journal"
VERSION = 2
#: versions read: 1 had no session lines
READ_VERSIONS = (1, 2)


@dataclass(frozen=True)
class Record:
    """One completed step. Angles in rad, power in W, time in s since 1970-01-01 UTC."""

    n: int
    kind: str
    i: int
    j: int
    command: tuple[float, float]
    readback: tuple[float, float]
    power: tuple[float, ...]
    time: float

    def line(self) -> bytes:
        """The record as one JSON line with its CRC (floats written exactly)."""
        body = asdict(self)
        return _with_crc(body)


def _with_crc(body: dict[str, Any]) -> bytes:
    text = json.dumps(body, sort_keys=True, separators=(",", ":"))
    crc = zlib.crc32(text.encode())
    return (text[:-1] + f',"crc":{crc}}}\n').encode()


def _parse(line: bytes) -> dict[str, Any] | None:
    """A line's content if it is complete and intact, else None."""
    if not line.endswith(b"\n"):
        return None
    try:
        body = json.loads(line)
    except (ValueError, UnicodeDecodeError):
        return None
    if not isinstance(body, dict) or "crc" not in body:
        return None
    crc = body.pop("crc")
    text = json.dumps(body, sort_keys=True, separators=(",", ":"))
    return body if zlib.crc32(text.encode()) == crc else None


def read_journal(path: str | Path) -> tuple[dict[str, Any], list[Record], int]:
    """Read a journal: (header, complete records, byte length of the intact part)."""
    contents = read_journal_sessions(path)
    return contents.header, contents.records, contents.good


class Contents(NamedTuple):
    """A journal as read: its header, complete records, the byte length of the intact part,
    the last session line's attributes ({} when none) and the line (1: the header) of each
    record, which session lines move from its step + 2."""

    header: dict[str, Any]
    records: list[Record]
    good: int
    session: dict[str, Any]
    lines: list[int]


def read_journal_sessions(path: str | Path) -> Contents:
    """:func:`read_journal` with the session lines' attributes and each record's line."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise JournalError(f"{path}: cannot read the journal ({exc.strerror})") from exc
    lines = data.splitlines(keepends=True)
    if not lines or (header := _parse(lines[0])) is None or header.get("format") != FORMAT:
        raise JournalError(f"{path}: not a raysim scan journal (bad or missing header)")
    if header.get("version") not in READ_VERSIONS:
        raise JournalError(f"{path}: journal version {header.get('version')} is not one of "
                           f"{', '.join(map(str, READ_VERSIONS))}")
    records: list[Record] = []
    numbers: list[int] = []
    session: dict[str, Any] = {}
    good = len(lines[0])
    for number, line in enumerate(lines[1:], start=2):
        body = _parse(line)
        if body is None:
            if number == len(lines) and not line.endswith(b"\n"):
                break  # a torn last line: the step it described was not completed
            if number == len(lines):  # one write ends every record with its newline
                raise JournalError(f"{path}: its last line {number} is complete but damaged (its "
                                   "check fails): not an interrupted write; restore the journal, "
                                   "or delete that line to take its step again")
            raise JournalError(f"{path}: line {number} is damaged and complete records follow it")
        if set(body) == {"session"} and isinstance(body["session"], dict):
            session = body["session"]
            good += len(line)
            continue
        try:
            record = Record(n=body["n"], kind=body["kind"], i=body["i"], j=body["j"],
                            command=tuple(body["command"]), readback=tuple(body["readback"]),
                            power=tuple(body["power"]), time=body["time"])
        except (KeyError, TypeError) as exc:
            raise JournalError(f"{path}: line {number} is not a step record") from exc
        problem = record_problem(record)
        if problem:  # a CRC guards against damage, not against a hand-edited or foreign journal
            raise JournalError(f"{path}: line {number} (step {record.n}) {problem}")
        if record.n != len(records):
            raise JournalError(f"{path}: line {number} holds step {record.n}, expected "
                               f"{len(records)} (records out of order or duplicated)")
        records.append(record)
        numbers.append(number)
        good += len(line)
    return Contents(header, records, good, session, numbers)


def _real(value: Any) -> bool:
    """Whether ``value`` is a finite JSON number (not a bool, a string or null)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def record_problem(record: Record) -> str:
    """What makes a record's values unusable, in words ("" when none): indices that are not
    integers, axes (rad) or a time (s) that are not finite numbers, or readings (W) that are
    not a non-empty list of finite powers > 0 (a power meter reads no 0 W nor a negative one)."""
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (record.n, record.i, record.j)) \
            or not isinstance(record.kind, str):
        return "has indices that are not integers"
    axes = (*record.command, *record.readback)
    if len(record.command) != 2 or len(record.readback) != 2 or not all(_real(v) for v in axes):
        return "has commanded or read-back axes that are not two finite numbers (rad)"
    if not _real(record.time):
        return "has a time that is not a finite number (s)"
    if not record.power:
        return "holds no power reading"
    for value in record.power:
        if not (_real(value) and value > 0):
            return f"holds the power reading {json.dumps(value)}, not a finite power > 0 W"
    return ""


class Journal:
    """An open journal to append completed steps to. Use :meth:`create` or :meth:`resume`."""

    def __init__(self, path: Path, fd: int, records: list[Record],
                 session: dict[str, Any] | None = None) -> None:
        self.path = path
        self._fd = fd
        self.records = records
        #: the last session line's attributes when resumed ({} for a new or version-1 journal)
        self.session = dict(session or {})

    @classmethod
    def create(cls, path: str | Path, fingerprint: str, steps: int, plan: str = "") -> Journal:
        """Start a new journal; refuse to overwrite one that holds records (a journal holding
        only its header, from a scan that failed before its first step, is replaced).
        ``plan``: the plan's own fingerprint (without the instruments' settings), so that
        ``--from-journal`` can tell the journal of another plan."""
        path = Path(path)
        if path.exists() and path.stat().st_size > 0:
            try:
                held = len(read_journal(path)[1])
            except JournalError as exc:
                raise JournalError(f"{path}: exists and is not a scan journal with no steps; not "
                                   "overwritten (move it away, or give another --journal)") from exc
            if held:
                raise JournalError(f"{path}: a journal of an earlier scan exists ({held} steps); pass "
                                   "--resume to continue it, or move it away to start afresh")
        path.parent.mkdir(parents=True, exist_ok=True)
        header = {"format": FORMAT, "version": VERSION, "fingerprint": fingerprint,
                  "steps": steps, "created": datetime.now(UTC).isoformat(timespec="seconds")}
        if plan:
            header["plan"] = plan
        # truncated only once locked: a scan already writing this journal keeps it
        fd = _locked(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND)
        os.ftruncate(fd, 0)
        journal = cls(path, fd, [])
        journal._write(_with_crc(header))
        _sync_dir(path.parent)
        return journal

    @classmethod
    def resume(cls, path: str | Path, fingerprint: str, steps: int, also: tuple[str, ...] = (),
               plans: tuple[str, ...] = ()) -> Journal:
        """Open an existing journal for appending, after checking it belongs to this plan:
        its fingerprint is ``fingerprint`` or one of ``also`` (what earlier versions wrote for
        the same plan and settings). ``plans``: this plan's own fingerprints (without the
        simulator's settings), to say which of the two differs.

        A torn last line is cut off first, so the next record starts on a fresh line.
        """
        path = Path(path)
        header, records, good, session, _ = read_journal_sessions(path)
        if header.get("fingerprint") not in (fingerprint, *also) or header.get("steps") != steps:
            if plans and header.get("plan") in plans and header.get("steps") == steps:
                raise JournalError(f"{path}: the journal was made with other settings of the "
                                   "simulated rig (its noise, drift, seed, gain, calibration or "
                                   "map) or of the probe; resume with the same options")
            raise JournalError(f"{path}: the journal belongs to another plan or other settings "
                               "(fingerprints differ); resume with the same plan and options")
        fd = _locked(path, os.O_WRONLY | os.O_APPEND)
        if os.fstat(fd).st_size != good:
            os.ftruncate(fd, good)
            os.fsync(fd)
        return cls(path, fd, records, session)

    def append(self, record: Record) -> None:
        """Write one completed step and sync it to disk before returning."""
        if record.n != len(self.records):
            raise JournalError(f"{self.path}: step {record.n} appended after "
                               f"{len(self.records)} records")
        self._write(record.line())
        self.records.append(record)

    def note_session(self, attrs: dict[str, Any]) -> None:
        """Write a session line: what the FieldMap says of the instruments that take the
        steps from here (flat attributes: strings and finite numbers), synced to disk."""
        values = {k: v for k, v in attrs.items() if isinstance(v, str) or _real(v)}
        self._write(_with_crc({"session": values}))

    def _write(self, blob: bytes) -> None:
        written = os.write(self._fd, blob)
        if written != len(blob):
            raise JournalError(f"{self.path}: short write to the journal (disk full?)")
        os.fsync(self._fd)

    def close(self) -> None:
        """Close the file (idempotent)."""
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1

    def __enter__(self) -> Journal:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _locked(path: Path, flags: int) -> int:
    """``path`` opened with ``flags`` and locked for this process alone (``flock``, released
    when the file is closed or the process dies); a journal another scan holds is refused."""
    fd = os.open(path, flags, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise JournalError(f"{path}: another scan is writing this journal; wait for it to end, "
                           "or give another output") from None
    return fd


@contextmanager
def not_being_written(path: str | Path) -> Iterator[None]:
    """Hold the journal at ``path`` still while it is read (a shared ``flock``: a scan cannot
    start appending meanwhile); refuse one that a scan is writing (it holds the exclusive
    lock): what is read would be a moment of a scan still going, and what is written from it
    that scan's output. A missing or unreadable file is left to its reader to report."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            raise JournalError(f"{path}: a scan is writing this journal; wait for it to end "
                               "(its FieldMap is written when it does)") from None
        yield
    finally:
        os.close(fd)


def _sync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
