"""Tables off a terminal keep every cell's full text, and ``--json`` carries the same numbers.

Off a terminal rich assumes 80 columns (here COLUMNS=60, narrower still) and used to fold or
cut cells ("readin…", "unbou…"). The JSON's numbers (SI units, full precision) are checked
against the printed text cell by cell, so the two forms cannot drift apart.
"""

from __future__ import annotations

import json

import pytest

from tests.raysim.pipeline.test_check import SMALL


@pytest.fixture
def narrow_cli(capfd, monkeypatch):
    """``raysim ARGS`` in this process with stdout a pipe 60 columns wide."""
    from tests.cli import run_in_process

    monkeypatch.setenv("COLUMNS", "60")
    return lambda *args: run_in_process(capfd, *args)


def cells(stdout: str) -> list[list[str]]:
    """The rows of the rich table in ``stdout`` (header first), each cell's text stripped."""
    return [[c.strip() for c in line.split(line[0])[1:-1]]
            for line in stdout.splitlines() if line[:1] in ("┃", "│")]


def test_budget_keeps_full_cells_and_its_json_has_the_same_numbers(narrow_cli, tmp_path):
    code, stdout, stderr = narrow_cli("budget", "scan_demo", "--target-um", "20",
                                      "--json", str(tmp_path / "b.json"))
    assert code == 0, stderr
    assert "…" not in stdout
    table = cells(stdout)
    assert table[0][:3] == ["noise (dB)", "readings", "RMS (um)"] and "readings for 20 um" in table[0]
    assert all(len(row) == len(table[0]) for row in table) and len(table) == 4
    assert any("unbounded (none)" in row for row in table)  # a cell that used to be cut
    data = json.loads((tmp_path / "b.json").read_text())
    assert data["columns"] == table[0] and data["rows"] == table[1:]
    for row, record in zip(table[1:], data["records"], strict=True):
        assert float(row[0]) == record["noise_db"]
        assert row[2] == f"{record['rms_m'] * 1e6:.2f}" and row[3] == f"{record['noise_m'] * 1e6:.2f}"
        assert record["delta_c_removed"] is True and record["rim_targets_m"] is None
        # the parts add in quadrature to the total (an independent check of the numbers)
        parts = record["noise_m"] ** 2 + record["references_m"] ** 2
        assert record["rms_m"] == pytest.approx(parts ** 0.5, rel=1e-9)
    # '-': the JSON alone on stdout, the same document
    code, stdout, _ = narrow_cli("budget", "scan_demo", "--target-um", "20", "--json", "-")
    assert code == 0 and json.loads(stdout) == data


def test_check_keeps_full_cells_and_its_json_has_the_same_numbers(narrow_cli, tmp_path):
    scene = tmp_path / "small.toml"
    scene.write_text(SMALL.format(panels=""))
    code, stdout, stderr = narrow_cli("check", str(scene), "--frequency", "1e9", "--grid", "32",
                                      "--refine", "0", "--refine-model", "none",
                                      "-o", str(tmp_path / "out"), "--json", str(tmp_path / "c.json"))
    assert code == 0, stderr
    assert "…" not in stdout
    table = cells(stdout)
    assert "error: GO data / GO-inverted / wave-refined (um)" in table[0] and len(table) == 2
    data = json.loads((tmp_path / "c.json").read_text())
    record, row = data["records"][0], dict(zip(table[0], table[1], strict=True))
    assert record["frequency_hz"] == 1e9
    assert row["FA diff"] == f"{100 * record['fa_difference']:.1f} %"
    assert row["ideal diff"] == f"{100 * record['ideal_difference']:.2f} %"
    assert data["verdict"][0] in stdout and data["page"].endswith("check.html")


def test_paper_json_has_the_printed_rows(narrow_cli, tmp_path):
    code, stdout, stderr = narrow_cli("paper", "--grid", "32", "--refine", "0", "--json", "-")
    assert code == 0, stderr
    data = json.loads(stdout)
    assert [r["method"] for r in data["records"]][:2] == ["FDM + Gauss-Seidel, 1000 iterations",
                                                           "FFT (enclosing square)"]
    for record, line in zip(data["records"], data["lines"][2:], strict=True):
        assert line.startswith(record["method"])
        assert f"{record['rrms'] * 100:7.3f} %" in line and f"{record['rms_m'] * 1e6:8.2f}" in line


def test_an_unwritable_json_file_is_refused_before_any_work(narrow_cli, tmp_path):
    result = narrow_cli("budget", "scan_demo", "--json", str(tmp_path))
    assert result.code == 2 and "is a folder" in result.error()
