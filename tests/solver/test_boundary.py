"""Rim targets: CSV contract, harmonic fit, and the rim values it gives."""

import numpy as np
import pytest

from solver.boundary import (
    RimTargets,
    check_targets,
    fit_harmonic,
    harmonic_order,
    read_rim_csv,
    write_rim_csv,
)
from solver.errors import RimTargetsError

A = 55.0


def write(tmp_path, text):
    path = tmp_path / "rim.csv"
    path.write_text(text)
    return path


def ring(n, r=A, jitter=0.0, seed=0):
    phi = np.linspace(0, 2 * np.pi, n, endpoint=False)
    phi = phi + jitter * np.random.default_rng(seed).standard_normal(n)
    return r * np.cos(phi), r * np.sin(phi)


def test_a_good_csv_reads_in_metres(tmp_path):
    x, y = ring(10)
    rows = "\n".join(f"{a:.6f},{b:.6f},{1e-4 * k:.6e}" for k, (a, b) in enumerate(zip(x, y, strict=True)))
    targets = read_rim_csv(write(tmp_path, "x,y,dz\n# laser tracker, 2026-11-22\n" + rows + "\n"))
    assert len(targets) == 10
    np.testing.assert_allclose(targets.dz, 1e-4 * np.arange(10))
    check_targets(targets, A)
    # a spreadsheet's "CSV UTF-8" starts with a byte-order mark: the same targets
    (tmp_path / "excel.csv").write_bytes(b"\xef\xbb\xbf" + (tmp_path / "rim.csv").read_bytes())
    again = read_rim_csv(tmp_path / "excel.csv")
    np.testing.assert_array_equal(again.dz, targets.dz)
    np.testing.assert_array_equal(again.x, targets.x)


@pytest.mark.parametrize(("text", "message"), [
    ("a,b,c\n1,2,3\n", "header x,y,dz"),
    ("", "header x,y,dz"),
    ("x,y,dz\n1,2\n", "row 2 has 2 fields"),
    ("x,y,dz\n1,2,3\n1,two,3\n", "row 3 is not three numbers"),
    ("x,y,dz\n1,2,nan\n", "row 2 holds a non-finite value"),
])
def test_malformed_csv_rows_are_named(tmp_path, text, message):
    with pytest.raises(RimTargetsError, match=message):
        read_rim_csv(write(tmp_path, text))


def test_missing_file_and_bad_target_sets_are_refused(tmp_path):
    with pytest.raises(RimTargetsError, match="no such"):
        read_rim_csv(tmp_path / "none.csv")
    x, y = ring(7)
    with pytest.raises(RimTargetsError, match="at least 8"):
        check_targets(RimTargets(x, y, np.zeros(7)), A)
    x, y = ring(12, r=1000 * A)                    # millimetres by mistake
    with pytest.raises(RimTargetsError, match="beyond"):
        check_targets(RimTargets(x, y, np.zeros(12)), A)
    x, y = ring(12)
    with pytest.raises(RimTargetsError, match="too large"):
        check_targets(RimTargets(x, y, np.full(12, 2.0)), A)


def test_the_fit_recovers_a_harmonic_polynomial_from_targets_off_the_rim():
    def h(x, y):
        r, p = np.hypot(x, y) / A, np.arctan2(y, x)
        return 3e-5 + 2e-4 * r**2 * np.cos(2 * p) - 5e-5 * r**3 * np.sin(3 * p) + 1e-5 * r * np.cos(p)

    x, y = ring(24, r=A, jitter=0.05)
    rr = A * (0.97 + 0.05 * np.random.default_rng(2).random(24))    # inside and outside
    phi = np.arctan2(y, x)
    x, y = rr * np.cos(phi), rr * np.sin(phi)
    targets = RimTargets(x, y, h(x, y))
    series = fit_harmonic(targets, targets.dz, A)
    test_phi = np.linspace(0, 2 * np.pi, 50)
    np.testing.assert_allclose(series(test_phi), h(A * np.cos(test_phi), A * np.sin(test_phi)),
                               atol=1e-12)
    np.testing.assert_allclose(series(test_phi, 0.5 * A),
                               h(0.5 * A * np.cos(test_phi), 0.5 * A * np.sin(test_phi)),
                               atol=1e-12)


def test_the_order_follows_count_and_gaps():
    x, y = ring(64)
    assert harmonic_order(RimTargets(x, y, np.zeros(64))) == 12
    x, y = ring(8)
    assert harmonic_order(RimTargets(x, y, np.zeros(8))) == 3
    phi = np.linspace(0, np.pi / 2, 20)                       # one quadrant only
    with pytest.raises(RimTargetsError, match="gap"):
        harmonic_order(RimTargets(A * np.cos(phi), A * np.sin(phi), np.zeros(20)))


def test_rim_csv_round_trip(tmp_path):
    """What write_rim_csv writes, read_rim_csv reads back to 9 significant digits."""
    phi = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
    targets = RimTargets(50.0 * np.cos(phi), 50.0 * np.sin(phi), 1e-5 * np.sin(3 * phi))
    path = tmp_path / "rim.csv"
    write_rim_csv(targets, path)
    back = read_rim_csv(path)
    for name in ("x", "y", "dz"):
        np.testing.assert_allclose(getattr(back, name), getattr(targets, name), rtol=1e-8,
                                   atol=1e-15)
