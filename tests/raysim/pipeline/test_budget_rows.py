"""budget_rows from Python refuses what the CLI's parser refuses (it answered -0.01 dB with the
budget of +0.01, NaN with a NaN total, 2.5 readings with 2.5 readings per point)."""

import numpy as np
import pytest

from raysim.pipeline.budget import budget_rows
from solver.errors import SolverError


@pytest.mark.parametrize(("kwargs", "says"), [
    ({"levels": [-0.01]}, "--noise-db values must lie in"),
    ({"levels": [float("nan")]}, "--noise-db values must lie in"),
    ({"levels": [0.0]}, "--noise-db values must lie in"),
    ({"levels": [100.0]}, "--noise-db values must lie in"),
    ({"levels": "0.01"}, "--noise-db values must lie in"),
    ({"levels": []}, "--noise-db values must lie in"),
    ({"levels": [0.01], "readings": 2.5}, "--readings must be an integer"),
    ({"levels": [0.01], "readings": "4"}, "--readings must be an integer"),
    ({"levels": [0.01], "rim": 8.5}, "--rim needs at least 8"),
    ({"levels": [0.01], "rim": -8}, "--rim needs at least 8"),
])
def test_bad_budget_requests_are_refused(kwargs, says):
    with pytest.raises(SolverError, match=says):
        budget_rows("scan_demo", **kwargs)


def test_a_good_request_still_answers():
    (row,) = budget_rows("scan_demo", [0.01], readings=4)
    assert row.readings == 4
    # numpy levels and counts, as a script passes them
    rows = budget_rows("scan_demo", np.array([0.01, 0.02]), readings=np.int64(4))
    assert [r.noise_db for r in rows] == [0.01, 0.02]


def test_a_count_beyond_the_cap_and_a_large_noise_are_said_so(tmp_path):
    """A target a million times too fine needed 4e20 readings per point, printed in full; noise
    of 3 dB per reading, where the linear model reads 17 % low against a Monte Carlo, came
    without a word."""
    from tests.cli import run_cli

    run = run_cli("budget", "scan_demo", "--noise-db", "0.01,3", "--target-um", "1e-9", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "readings for 1e-09 um" in run.stdout
    assert "more than 100000" in run.stdout or "out of reach" in run.stdout
    assert not any(len(word) > 12 and word.isdigit() for word in run.stdout.split())
    assert "linear noise model underestimates" in run.stdout


def test_the_removed_terms_reach_the_table_and_the_json(tmp_path):
    """``--remove tilt`` as ``invert --remove tilt``: every part loses its share along tilt (the
    noise, the references and the rim targets' m = 1 term), the JSON names the terms."""
    import json

    from tests.cli import run_cli

    (kept,) = budget_rows("scan_paper", [0.01], rim=64)
    (removed,) = budget_rows("scan_paper", [0.01], rim=64, remove="tilt")
    assert removed.budget.removed == ("tilt",)
    b, k = removed.budget, kept.budget
    assert b.noise < 0.95 * k.noise and b.reference < 0.95 * k.reference
    assert b.harmonic < 0.95 * k.harmonic
    run = run_cli("budget", "scan_paper", "--noise-db", "0.01", "--rim", "64", "--remove", "tilt",
                  "--json", "b.json", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "removed after the solve (as invert --remove): tilt" in run.stdout
    (record,) = json.loads((tmp_path / "b.json").read_text())["records"]
    assert record["removed_terms"] == ["tilt"]
    assert record["rms_m"] == pytest.approx(b.total)


def test_a_plan_without_rim_targets_is_told_its_rms_leaves_out_the_harmonic_part(tmp_path):
    """Without rim targets the table's RMS left out the unbounded harmonic part and read lower
    than the same plan's with 64 targets (5.62 against 6.23 um for scan_paper at 0.001 dB),
    with no word that the two are not comparable."""
    from tests.cli import run_cli

    (bare,) = budget_rows("scan_paper", [0.001])
    (rim,) = budget_rows("scan_paper", [0.001], rim=64)
    assert bare.budget.harmonic is None and bare.budget.total < rim.budget.total  # the trap
    without = run_cli("budget", "scan_paper", "--noise-db", "0.001", cwd=tmp_path)
    with_rim = run_cli("budget", "scan_paper", "--noise-db", "0.001", "--rim", "64", cwd=tmp_path)
    assert without.returncode == with_rim.returncode == 0
    assert "WARNING: without rim targets the RMS leaves out the harmonic part" in without.stdout
    assert "WARNING" not in with_rim.stdout
