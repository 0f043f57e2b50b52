"""The scan journal: exact round trip, torn last lines, corruption, ownership."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from hardware.errors import JournalError
from hardware.journal import Journal, Record, read_journal


def record(n: int) -> Record:
    return Record(n, "sample" if n else "reference", n % 3, n // 3,
                  (0.1 * n + 1e-17, math.pi / 7), (0.1 * n, math.pi / 7 - 1e-9),
                  (1.2345678901234567e-5 * (n + 1), 3.3e-6), 1.7e9 + n / 3)


def test_round_trip_is_exact(tmp_path: Path) -> None:
    path = tmp_path / "scan.nc.journal"
    with Journal.create(path, "abc", 10) as jr:
        for n in range(4):
            jr.append(record(n))
    header, records, good = read_journal(path)
    assert header["fingerprint"] == "abc" and header["steps"] == 10
    assert records == [record(n) for n in range(4)]
    assert good == path.stat().st_size


def test_torn_last_line_is_ignored_and_cut_on_resume(tmp_path: Path) -> None:
    path = tmp_path / "j"
    with Journal.create(path, "abc", 10) as jr:
        for n in range(3):
            jr.append(record(n))
    intact = path.read_bytes()
    torn = record(3).line()[:-17]
    path.write_bytes(intact + torn)
    _, records, good = read_journal(path)
    assert len(records) == 3 and good == len(intact)
    with Journal.resume(path, "abc", 10) as jr:
        assert path.read_bytes() == intact
        jr.append(record(3))
    assert [r.n for r in read_journal(path)[1]] == [0, 1, 2, 3]


def test_complete_line_without_newline_counts_as_torn(tmp_path: Path) -> None:
    path = tmp_path / "j"
    with Journal.create(path, "abc", 10) as jr:
        jr.append(record(0))
    path.write_bytes(path.read_bytes() + record(1).line().rstrip(b"\n"))
    assert len(read_journal(path)[1]) == 1


def test_damage_before_good_records_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "j"
    with Journal.create(path, "abc", 10) as jr:
        for n in range(3):
            jr.append(record(n))
    lines = path.read_bytes().splitlines(keepends=True)
    lines[2] = lines[2].replace(b'"i":1', b'"i":2')          # a flipped digit: CRC mismatch
    path.write_bytes(b"".join(lines))
    with pytest.raises(JournalError, match="line 3 is damaged"):
        read_journal(path)


def test_a_complete_last_line_that_fails_its_check_is_an_error(tmp_path: Path) -> None:
    """QA: an edited digit in the last line, complete with its newline, was dropped as a torn
    write and the step taken again without a word; a write torn by a kill has no newline."""
    path = tmp_path / "j"
    with Journal.create(path, "abc", 10) as jr:
        for n in range(3):
            jr.append(record(n))
    lines = path.read_bytes().splitlines(keepends=True)
    lines[-1] = lines[-1].replace(b'"i":2', b'"i":3')
    path.write_bytes(b"".join(lines))
    with pytest.raises(JournalError, match="last line 4 is complete but damaged"):
        read_journal(path)


def test_duplicate_or_reordered_records_are_errors(tmp_path: Path) -> None:
    path = tmp_path / "j"
    with Journal.create(path, "abc", 10) as jr:
        jr.append(record(0))
        jr.append(record(1))
        with pytest.raises(JournalError, match="step 1 appended after 2"):
            jr.append(record(1))
    path.write_bytes(path.read_bytes() + record(1).line())
    with pytest.raises(JournalError, match="holds step 1, expected 2"):
        read_journal(path)


def test_ownership_and_overwrite(tmp_path: Path) -> None:
    path = tmp_path / "j"
    with Journal.create(path, "abc", 10) as jr:
        jr.append(record(0))
    before = path.read_bytes()
    with pytest.raises(JournalError, match="pass --resume"):
        Journal.create(path, "abc", 10)
    with pytest.raises(JournalError, match="belongs to another plan"):
        Journal.resume(path, "xyz", 10)
    with pytest.raises(JournalError, match="belongs to another plan"):
        Journal.resume(path, "abc", 11)
    assert path.read_bytes() == before


def test_not_a_journal(tmp_path: Path) -> None:
    path = tmp_path / "j"
    path.write_text("hello\n")
    with pytest.raises(JournalError, match="not a raysim scan journal"):
        read_journal(path)


def test_a_journal_holding_only_its_header_never_blocks_the_next_scan(tmp_path):
    """A scan that failed before its first step left a header: a new scan replaces it, with or
    without --resume, whatever plan made it; a journal with steps, or another file, is kept."""
    from hardware.journal import Journal, JournalError

    path = tmp_path / "scan.nc.journal"
    Journal.create(path, "fingerprint-a", 10).close()
    with Journal.create(path, "fingerprint-b", 12) as journal:  # another plan: fine, no steps
        journal.append(Record(0, "reference", -1, -1, (0.0, 0.0), (0.0, 0.0), (1e-5,), 0.0))
    with pytest.raises(JournalError, match="1 steps"):
        Journal.create(path, "fingerprint-b", 12)
    other = tmp_path / "notes.txt"
    other.write_text("not a journal\n")
    with pytest.raises(JournalError, match="not overwritten"):
        Journal.create(other, "fingerprint-a", 10)
    assert other.read_text() == "not a journal\n"
