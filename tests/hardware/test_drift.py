"""Drift from the reference readings: the gain models and the test for real drift."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hardware.drift import best_window, chi2_limit, drift, reading_noise, reduced_chi2, reference_gains
from hardware.journal import Record


def test_reference_gains_modes() -> None:
    index = np.arange(0.0, 4000.0, 100.0)
    linear = 1.0 + 2e-6 * index                      # a linear drift
    assert np.array_equal(reference_gains(index, 3e-5 * linear, "none", 5), np.ones(40))
    assert np.allclose(reference_gains(index, 3e-5 * linear, "linear", 5), linear, rtol=1e-14)
    # a straight-line fit keeps a linear drift exactly
    assert np.allclose(reference_gains(index, 3e-5 * linear, "smooth", 5), linear, rtol=1e-12)
    # and divides the reading noise by about sqrt(5) inside the series
    rng = np.random.default_rng(8)
    index = np.arange(0.0, 4e5, 100.0)
    noisy = 1.0 + 1e-3 * rng.standard_normal(index.size)
    smooth = reference_gains(index, noisy, "smooth", 5) * noisy[0]
    assert np.std(smooth[10:-10] - 1.0) == pytest.approx(1e-3 / math.sqrt(5), rel=0.1)


def test_reduced_chi2_of_noise_is_one() -> None:
    rng = np.random.default_rng(9)
    sem = np.full(2000, 2e-4)
    power = 1.0 + sem * rng.standard_normal(2000)
    assert reduced_chi2(power, sem) == pytest.approx(1.0, abs=0.1)
    assert math.isnan(reduced_chi2(power[:1], sem[:1]))
    assert math.isnan(reduced_chi2(power, np.zeros(2000)))
    assert chi2_limit(19) == pytest.approx(1.0 + 3.0 / 3.0)


def records(gains: np.ndarray, noise: float, count: int, seed: int) -> list[Record]:
    rng = np.random.default_rng(seed)
    return [Record(100 * m, "reference", -1, -1, (0.0, 0.0), (0.0, 0.0),
                   tuple(1e-5 * g * (1.0 + noise * rng.standard_normal(count))), 0.0)
            for m, g in enumerate(gains)]


def test_auto_removes_drift_only_when_the_references_show_it() -> None:
    flat = drift(records(np.ones(30), 2e-3, 16, seed=1), "auto", 9)
    assert flat.applied == "none" and np.all(flat.gains == 1.0)
    assert flat.chi2 < chi2_limit(30)
    ramp = 1.0 + 0.01 * np.linspace(0.0, 1.0, 30)      # 1 % over the scan, 20x the noise
    moving = drift(records(ramp, 2e-3, 16, seed=1), "auto", 9)
    assert moving.applied == "smooth" and moving.window == 9
    assert np.allclose(moving.gains, ramp, atol=1.5e-3)
    assert moving.at(50.0) == pytest.approx(0.5 * (moving.gains[0] + moving.gains[1]))
    # quiet references (one reading, or no scatter) cannot rule drift out; an exactly
    # linear drift is predicted perfectly by every window, so either correction is right,
    # and both must give the drift itself
    quiet = drift(records(ramp, 0.0, 1, seed=1), "auto", 9)
    assert quiet.applied in ("linear", "smooth")
    assert np.allclose(quiet.gains, ramp / ramp[0], rtol=1e-12)
    assert drift(records(np.ones(3), 0.0, 4, seed=1), "linear", 9).applied == "linear"


def test_window_follows_drift_speed_and_noise() -> None:
    """Leave-one-out picks no smoothing for a drift fast against the reference spacing and
    quiet references, and a wide window for a slow drift under noisy references."""
    index = np.arange(0.0, 3600.0 * 40, 3600.0)
    rng = np.random.default_rng(4)
    fast = 1.0 + 0.01 * np.sin(2 * np.pi * index / 40000.0) + 1e-5 * rng.standard_normal(40)
    assert best_window(index, fast, 9) == 1
    slow = 1.0 + 1e-7 * index / 3600.0 + 3e-4 * rng.standard_normal(40)
    assert best_window(index, slow, 9) >= 5
    fast_drift = drift(records(fast, 1e-4, 16, seed=2), "auto", 9)
    assert fast_drift.applied == "linear" and fast_drift.window == 1
    assert np.allclose(fast_drift.gains, fast / fast[0], atol=1e-4)


def test_exact_predictions_tie_to_the_smallest_window() -> None:
    """Noise-free linear references: every window predicts each one to round-off, so the
    choice is a tie by construction; it goes to no smoothing whatever the last bits say,
    here over drifts of several sizes and slopes of both signs."""
    index = np.arange(0.0, 3000.0, 100.0)
    for slope in (-3e-6, 1e-9, 2e-7, 5e-6):
        for scale in (1e-9, 1e-5, 1.0):
            power = scale * (1.0 + slope * index)
            assert best_window(index, power, 9) == 1
    # and a real preference is still seen past the floor: slow drift under noise
    rng = np.random.default_rng(12)
    noisy = 1e-5 * (1.0 + 1e-8 * index + 1e-4 * rng.standard_normal(index.size))
    assert best_window(index, noisy, 9) > 1


def test_references_of_one_reading_take_their_noise_from_the_scans_cells() -> None:
    """References of one reading state no scatter, so auto corrected every such scan: with no
    drift it applied the noise of 30 single readings line by line (a map 3x worse than
    uncorrected). The cells' readings give the meter's noise: without drift auto now leaves
    the scan alone, and a drift 20 times the noise is still removed."""
    rng = np.random.default_rng(4)
    cells = [Record(2 * m + 1, "sample", 0, m, (0.0, 0.0), (0.0, 0.0),
                    tuple(1e-5 * (1.0 + 2e-3 * rng.standard_normal(4))), 0.0) for m in range(60)]
    flat = records(np.ones(30), 2e-3, 1, seed=1)
    noise = reading_noise(cells, flat)
    assert noise == pytest.approx(2e-3, rel=0.15)
    assert drift(flat, "auto", 9).applied != "none"  # nothing tells the noise: it must correct
    quiet = drift(flat, "auto", 9, noise)
    assert quiet.applied == "none" and np.all(quiet.gains == 1.0)
    ramp = 1.0 + 0.04 * np.linspace(0.0, 1.0, 30)
    moving = drift(records(ramp, 2e-3, 1, seed=1), "auto", 9, noise)
    assert moving.applied in ("linear", "smooth")
    left = moving.gains * moving.power[0] / 1e-5 - ramp  # the gains against the true drift
    assert np.sqrt(np.mean(left**2)) < 0.1 * 0.04
    # cells far dimmer than the references (noisier, relatively) are not pooled
    dim = [Record(r.n, "sample", 0, 0, (0.0, 0.0), (0.0, 0.0), tuple(1e-3 * np.asarray(r.power)), 0.0)
           for r in cells]
    assert reading_noise(dim, records(np.ones(30), 0.0, 1, seed=1)) is None


def test_smooth_follows_a_drift_its_line_cannot() -> None:
    """QA: with 9 references and the demo's window of 9, smooth drew ONE line through a drift
    that dipped by 0.094 dB and came back, leaving 0.049 dB RMS of it in the intensities (a
    1094 um surface from a 36 um map) and said nothing. The references miss such a line by
    far more than their noise: smooth now follows them and says so; a drift the line does
    follow (a ramp under noise) keeps the whole window."""
    true = 10.0 ** (-0.094 / 10.0 * np.sin(np.pi * np.arange(9) / 8.0))  # the dip and back
    asked = drift(records(true, 2.3e-3, 16, seed=3), "smooth", 9)
    assert asked.applied == "linear" and asked.window == 1
    assert "followed the references" in asked.note
    sem = 2.3e-3 / 4.0  # of a mean of 16 readings, relative
    assert np.max(np.abs(asked.gains - true / true[0])) < 5 * sem
    # the noise-free case (a simulation): the line is refused outright, the drift followed exactly
    exact = drift(records(true, 0.0, 16, seed=3), "smooth", 9)
    assert exact.applied == "linear" and np.allclose(exact.gains, true / true[0], rtol=1e-12)
    ramp = 1.0 + 0.01 * np.linspace(0.0, 1.0, 30)
    kept = drift(records(ramp, 2e-3, 16, seed=1), "smooth", 9)
    assert kept.applied == "smooth" and kept.window == 9 and kept.note == ""
    assert kept.fit_chi2 < 1.0 + 3.0 * math.sqrt(2.0 / 20.0)
    # auto's leave-one-out choice gets the same check
    auto = drift(records(true, 2.3e-3, 16, seed=3), "auto", 9)
    assert np.max(np.abs(auto.gains - true / true[0])) < 5 * sem


def test_auto_leaves_a_drift_free_scan_of_two_readings_a_reference_alone() -> None:
    """Each reference's own spread from 2 readings is a chi-square of one degree of freedom:
    some came out tiny, and the references of a drift-free scan scattered "11 times their
    noise" about their mean (limit 2.4), so auto corrected the scan by its references' noise.
    The noise is now pooled over the references; a drift 20 times the noise is still found."""
    corrected = [drift(records(np.ones(30), 2e-3, 2, seed=s), "auto", 9).applied != "none"
                 for s in range(20)]
    assert sum(corrected) <= 2                         # the 3-sigma limit's false alarms
    ramp = 1.0 + 0.01 * np.linspace(0.0, 1.0, 30)
    moving = drift(records(ramp, 2e-3, 2, seed=3), "auto", 9)
    assert moving.applied != "none" and np.allclose(moving.gains, ramp, atol=4e-3)
