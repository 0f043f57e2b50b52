"""Receiver drift from the reference readings: whether there is any, and the gain to remove.

Every K lines the probe returns to a fixed reference position; the mean of its readings
there, relative to the first reference, is the receiver's gain at that moment. Removing it
helps only when the drift exceeds the noise of the references: the scan's intensities must
be right to about 5e-5 in the ratio, and a noisy gain estimate applied line by line is a
phi-dependent error the inversion turns into surface error. Hence ``auto``: the gains are
tested against their own reading noise (reduced chi-square of the reference means about
their weighted mean) and removed only when the drift is significant; then the smoothing
that best predicts each reference from the others (leave-one-out) is used, from plain
interpolation (a drift fast against the reference spacing) to line fits over
``drift_window`` references (a slow drift under noisy references).

A line fit can only follow a drift that is straight over its window: with the demo's window
of 9 and 9 references, ``smooth`` drew one line through a drift that dipped by 0.094 dB and
came back, and left 0.049 dB RMS of it in the intensities (linear: 0.0025 dB), 1094 um RMS
in the inverted surface. So every smoothing is checked against the references themselves:
their scatter about the fitted gains, in units of their noise, must be what noise alone
gives (:func:`fit_chi2`, below :func:`chi2_limit`); otherwise the window is narrowed to the
widest that passes, and where none does the references are followed as they are (linear).
The Drift says so in ``note`` (the FieldMap's ``drift_note``, the scan's summary line).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hardware.journal import Record

#: auto: none unless the references show significant drift, then linear or smooth with the
#: window chosen by leave-one-out prediction; none: record the references only; linear:
#: interpolate their gains; smooth: local straight-line fits over ``window`` references.
DRIFT_MODES = ("auto", "none", "linear", "smooth")


@dataclass(frozen=True)
class Drift:
    """The references of a scan and the gain taken from them.

    ``index``: step indices; ``power``: mean readings (W); ``gains``: the gain removed at
    each reference, relative to the first; ``applied``: the mode used (``auto`` resolved);
    ``window``: the smoothing window used (1 without smoothing); ``chi2``: reduced
    chi-square of the reference means (NaN when it cannot be formed); ``fit_chi2``: that of
    the references about the smoothed gains (:func:`fit_chi2`; NaN without smoothing or
    without their noise); ``note``: why the correction differs from the one asked ("" if not).
    """

    index: np.ndarray
    power: np.ndarray
    gains: np.ndarray
    applied: str
    window: int
    chi2: float
    fit_chi2: float = math.nan
    note: str = ""

    def at(self, n: float) -> float:
        """Gain at step ``n``: linear between the references, held beyond them."""
        return float(np.interp(n, self.index, self.gains)) if self.index.size else 1.0


def drift(references: Sequence[Record], mode: str, window: int,
          reading_noise: float | None = None) -> Drift:
    """The drift of a scan from its reference records, corrected per ``mode``.

    ``reading_noise``: the relative standard deviation of one reading, from elsewhere in the
    scan (:func:`reading_noise`); it stands in for a reference of one reading, whose own
    scatter is unknown (without it such references cannot rule drift out, and ``auto``
    corrects)."""
    index = np.array([r.n for r in references], dtype=np.float64)
    power = np.array([np.mean(r.power) for r in references])
    sem = reference_noise(references, power, reading_noise)
    chi2 = reduced_chi2(power, sem)
    applied = mode
    if mode == "auto":
        applied = "none"
        if not math.isfinite(chi2) or chi2 > chi2_limit(index.size):
            window = best_window(index, power, window)
            applied = "linear" if window == 1 else "smooth"
    if applied != "smooth":
        window = 1
    fit, note = math.nan, ""
    if applied == "smooth" and min(window, index.size) >= 3:
        asked = min(window, index.size)
        # with the pooled noise (reference_noise): a reference's own spread from 2 readings
        # made quiet references miss a line by "450x their noise", and the check followed noise
        window, fit = widest_consistent(index, power, sem, asked)
        if window < asked:
            far = fit_chi2(index, power, sem, asked)
            note = (f"line fits over {asked} references miss them by {math.sqrt(far):.3g}x their "
                    "noise (rms); " + ("followed the references (linear) instead" if window == 1
                                       else f"smoothed over {window} instead"))
            if window == 1:
                applied = "linear"
    gains = reference_gains(index, power, applied, window)
    return Drift(index, power, gains, applied, window, chi2, fit, note)


def smoothed(index: np.ndarray, values: np.ndarray, window: int) -> np.ndarray:
    """Each of ``values`` replaced by a straight-line least-squares fit over the ``window``
    references around it (fewer at the ends); linear in ``values``."""
    fitted = np.empty(values.shape, dtype=np.float64)
    width = min(window, index.size)
    for m in range(index.size):
        lo = min(max(m - width // 2, 0), index.size - width)
        x, y = index[lo:lo + width], values[lo:lo + width]
        slope, offset = np.polyfit(x - x.mean(), y, 1)
        fitted[m] = offset + slope * (index[m] - x.mean())
    return fitted


def fit_chi2(index: np.ndarray, power: np.ndarray, sem: np.ndarray, window: int) -> float:
    """Scatter of the reference means (W) about their line fits over ``window`` references,
    in units of their noise ``sem`` (W): the sum of the squared residuals over sem^2, divided
    by what noise alone gives on average (:func:`fit_freedom`), so about 1 when the fits
    follow the drift. NaN when the noise is unknown or the fits leave no freedom. Noise below
    the round-off of the readings (1e-10 of each, as in :func:`best_window`) counts as that:
    noise-free references (a simulation, 16 equal readings) must be followed exactly."""
    freedom = fit_freedom(index, window)
    if freedom < 1e-9 or not np.all(np.isfinite(sem)):
        return math.nan
    sem = np.maximum(sem, 1e-10 * np.abs(power))
    return float(np.sum(((power - smoothed(index, power, window)) / sem) ** 2) / freedom)


def fit_freedom(index: np.ndarray, window: int) -> float:
    """Degrees of freedom noise keeps about the line fits over ``window`` references: the
    trace of (I - S)^T (I - S), S the smoother's matrix (exact for equal noise; 0 where the
    fits go through every reference, 3 references or fewer)."""
    if index.size < 3:
        return 0.0
    rest = np.eye(index.size) - np.column_stack([smoothed(index, e, window)
                                                 for e in np.eye(index.size)])
    return float(np.trace(rest.T @ rest))


def widest_consistent(index: np.ndarray, power: np.ndarray, sem: np.ndarray,
                         window: int) -> tuple[int, float]:
    """The widest window, ``window`` down to 3, whose line fits the references agree with
    within their noise (:func:`fit_chi2` at most 3 sigma of its own spread above 1, as
    :func:`chi2_limit`), and its fit chi-square; (1, NaN) when none does: the references are
    then followed as they are. A window whose fit cannot be checked (unknown noise, no
    freedom) is kept as asked."""
    for width in range(window, 2, -1):
        value = fit_chi2(index, power, sem, width)
        limit = 1.0 + 3.0 * math.sqrt(2.0 / max(fit_freedom(index, width), 1e-9))
        if not math.isfinite(value) or value <= limit:
            return width, value
    return 1, math.nan


def best_window(index: np.ndarray, power: np.ndarray, largest: int) -> int:
    """The smoothing window (1: none) whose fits best predict each reference from the others.

    Window w >= 3 fits a line to the w - 1 nearest other references; window 1 draws it
    through the 2 nearest (interpolation between the neighbours). Mean squared prediction
    error over all references; the smallest wins. A window must beat the best so far by more
    than a part in 1e6, and errors below the round-off floor of the readings (1e-10 of their
    mean, squared) count as that floor: references that every window predicts exactly (a
    noise-free linear drift) are a tie, and a tie goes to the smaller window by construction,
    not by the last bits of the arithmetic.
    """
    if index.size < 4:
        return 1
    floor = index.size * (1e-10 * float(np.mean(np.abs(power)))) ** 2
    best, best_error = 1, math.inf
    for window in [1, *range(3, min(largest, index.size) + 1)]:
        others = 2 if window == 1 else window - 1
        error = 0.0
        for m in range(index.size):
            rest = np.delete(np.arange(index.size), m)
            near = rest[np.argsort(np.abs(index[rest] - index[m]), kind="stable")[:others]]
            x, y = index[near], power[near]
            slope, offset = np.polyfit(x - x.mean(), y, 1)
            error += (offset + slope * (index[m] - x.mean()) - power[m]) ** 2
        error = max(error, floor)
        if error < best_error * (1.0 - 1e-6):
            best, best_error = window, error
    return best


def reference_noise(references: Sequence[Record], power: np.ndarray,
                    reading_noise: float | None = None) -> np.ndarray:
    """The standard error (W) of each reference's mean reading ``power``: one reading's relative
    noise, pooled over the references of two or more readings (else ``reading_noise``, from
    the scan's cells; NaN without either), over the square root of its count. Pooled, not each
    reference's own: from 2 readings one reference's spread can be tiny by chance (a
    chi-square of one degree of freedom), and a drift-free scan's references then scattered
    "11 times their noise", so ``auto`` corrected noise."""
    spread = [np.var(r.power, ddof=1) / np.mean(r.power) ** 2 for r in references if len(r.power) > 1]
    own = reading_noise if reading_noise is not None and reading_noise > 0 else np.nan
    relative = math.sqrt(float(np.mean(spread))) if spread else own
    return np.array([relative * p / math.sqrt(len(r.power)) for r, p in zip(references, power, strict=True)])


def reading_noise(samples: Sequence[Record], references: Sequence[Record]) -> float | None:
    """The relative standard deviation of one reading (pooled variance of the readings about
    their cell's mean, over the sample records of two or more readings and at least half the
    references' mean power: a meter's relative noise grows where the power is low); None
    without such records."""
    level = 0.5 * float(np.mean([np.mean(r.power) for r in references])) if references else 0.0
    spread = [np.var(r.power, ddof=1) / np.mean(r.power) ** 2 for r in samples
              if len(r.power) > 1 and np.mean(r.power) >= level]
    return float(math.sqrt(np.mean(spread))) if spread else None


def reduced_chi2(power: np.ndarray, sem: np.ndarray) -> float:
    """Scatter of the reference means about their weighted mean, in units of their noise."""
    if power.size < 2 or not np.all(np.isfinite(sem)) or np.any(sem <= 0):
        return math.nan
    weight = 1.0 / sem**2
    mean = np.sum(weight * power) / np.sum(weight)
    return float(np.sum(weight * (power - mean) ** 2) / (power.size - 1))


def chi2_limit(count: int) -> float:
    """Reduced chi-square above which drift counts as real: 3 sigma above the noise's 1."""
    return 1.0 + 3.0 * math.sqrt(2.0 / max(count - 1, 1))


def reference_gains(index: np.ndarray, power: np.ndarray, mode: str,
                    window: int) -> np.ndarray:
    """Receiver gain at each reference reading relative to the first (1 = as calibrated).

    ``index``: step indices of the references; ``power``: their mean readings (W). ``mode``
    ``linear`` takes the readings as they are; ``smooth`` replaces each by a straight-line
    least-squares fit over the ``window`` references around it (fewer at the ends), which
    keeps a linear drift exactly and divides the reading noise by about sqrt(window);
    ``none`` returns ones.
    """
    if mode == "none" or index.size == 0:
        return np.ones(index.size)
    gains = power / power[0]
    if mode == "smooth" and index.size > 2:
        fitted = smoothed(index, gains, window)
        gains = fitted / fitted[0]
    return gains
