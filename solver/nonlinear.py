"""Model-based refinement: remove the linearisation error of the deformation-intensity equation.

Frame and units: sphere data on the FieldMap's (theta, phi) grid (rad), FA dimensionless; the
surface on the aperture grid (x, y in m), delta in m.

The paper's equation FA = G Laplacian(delta) drops second-order terms and takes the deformed
ray's sphere point P* as the ideal one P; fed exact GO data it errs by about 9 % RMS on the
paper's case, almost all piston and focus, growing with the square of the deformation. Defect
correction with a GO forward model removes it: with F_model(delta) the model's FA on the
sphere and L^-1 the linear inversion (resample, divide by G, Poisson solve),

    delta_{k+1} = delta_k + L^-1( FA_measured - F_model(delta_k) ),

a fixed-point iteration whose fixed point makes the model reproduce the measured FA on every
usable sphere cell. The linear operator misses a few slow, low-order directions of the model's
Jacobian (plain defect correction gains only a factor of about 0.6 per step on the paper's
case), so the iterates are combined by Anderson acceleration (Walker & Ni, SIAM J. Numer.
Anal. 49, 1715, 2011; depth ``memory``): the next iterate is the combination of the last few
that minimises the linearised update, which removes those directions in one or two steps.
The model needs only what every FieldMap carries: F, D, R and the grid (and, for the wave
models, the frequency and polarisation): see :mod:`solver.forward`. The default model is the
project's own GO engine (:func:`raysim.optics.go.forward_intensity`) on the current estimate as a
gridded map; the PO engine (``po``, ``po+ptd``) or any callable with the same signature can
stand in, with the preconditioner of :mod:`solver.wave` in place of the GO inversion (the
GO inversion alone lets the PO iteration diverge after two steps: PO responds to the smooth
shapes through the edge wave, and to the fine ones with a Fresnel attenuation GO lacks). The
preconditioner sets how fast the iteration converges; the fixed point is the model's.

The step is safeguarded by the misfit itself: every update is run through the model before it
is kept, and one that raises the misfit is halved until it lowers it enough (a backtracking
line search along the update, with Armijo's sufficient-decrease test). The linear operator
overestimates the step where the terms the equation drops are large: with the sphere radius
near F (R >= 0.85 F) the first full step raised the misfit, while half of it converged.

Misfits may be weighted per sphere cell (``weight``: the amplitude weight of
:func:`solver.wave.amplitude_weight`, 1 for GO data) and, with ``fit_gain``, the scan's scale
is an unknown beside the surface: ``correct`` then returns a gain step too, and the measured
1 + FA is multiplied by the running factor gamma (GO keeps its exact power-balance scale).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray

from raysim.maps.sphere import SphereGrid
from raysim.progress import Progress, silent, within
from solver.aperture import ApertureGrid
from solver.continuation import RimContinuation, rim_continuation
from solver.equation import intensity_ratio_fa, misfit_noise_rms
from solver.forward import Forward, ForwardModel, as_model, go_forward
from solver.resample import modelled_rows

__all__ = ["Correct", "Forward", "ForwardModel", "RefineHistory", "anderson_step", "extend_outside",
           "go_forward", "outside_fill", "refine"]


@dataclass
class RefineHistory:
    """What the refinement did, one entry per map whose misfit was measured and kept.

    ``misfit_rms`` (weighted FA misfit on the compared cells, dimensionless) and ``gain_factor``
    (the scale gamma on the measured 1 + FA; 1 unless the gain is fitted) have one entry for
    the starting map and one per accepted update, so their last entries are those of the
    returned map. ``update_rms`` (m) is the RMS over the aperture of each accepted update as
    applied (after Anderson's combination and any shortening), ``backtracks`` how many times
    each was halved before the misfit fell. ``evaluations`` counts the forward-model runs, the
    ideal reflector's and those of rejected trial maps included.
    """

    update_rms: list[float] = field(default_factory=list)
    misfit_rms: list[float] = field(default_factory=list)
    gain_factor: list[float] = field(default_factory=list)
    backtracks: list[int] = field(default_factory=list)
    evaluations: int = 0
    seconds: float = 0.0
    stopped: str = ""  # why the loop ended before its iterations, "" when it ran them all


def outside_fill(D: float, N: int) -> RimContinuation:
    """The continuation into the points outside the disk of the grid (D, N)
    (:class:`solver.continuation.RimContinuation`), built once per grid."""
    return rim_continuation(float(D), int(N))


def extend_outside(grid: ApertureGrid, delta: NDArray[np.float64]) -> NDArray[np.float64]:
    """``delta`` (m) with the points outside the aperture holding its continuation: near the
    rim the map's own local quadratic, beyond it a discrete Laplace fill
    (:mod:`solver.continuation`).

    Gives the forward model a surface whose slope and curvature run on through the rim, up to
    the corners of the square grid.
    """
    return outside_fill(float(grid.D), int(grid.N))(delta)


Correct = Callable[[NDArray[np.float64], NDArray[np.float64]],
                   NDArray[np.float64] | tuple[NDArray[np.float64], float]]


def refine(delta: NDArray[np.float64], fa_measured: NDArray[np.float64], sphere: SphereGrid,
           F: float, D: float, grid: ApertureGrid, n_rows: int, correct: Correct,
           iterations: int, forward: ForwardModel | Forward | None = None, device: str | None = "cpu",
           memory: int = 3, weight: NDArray[np.float64] | None = None, fit_gain: bool = False,
           progress: Progress | None = None,
           noise_variance: float = 0.0) -> tuple[NDArray[np.float64], RefineHistory]:
    """Refine ``delta`` (m, (N, N)) by defect correction against the measured FA on the sphere.

    Every map the loop returns has had its misfit measured: each update is evaluated with the
    forward model before it is kept. One that raises the misfit is halved (at most
    :data:`MAX_BACKTRACKS` times, one forward run each) and the first shortened step that
    lowers the misfit enough (:data:`SUFFICIENT_DECREASE`) is kept; when none does, or when the
    update before removed less than that share (the misfit near its floor), the loop stops with
    the map before it. It also stops when an update changes the misfit by less than
    :data:`MISFIT_TOLERANCE`, keeping the update only if it is no worse.

    Parameters
    ----------
    delta : starting estimate (the linear solution), NaN outside the aperture.
    fa_measured : FA on the sphere grid, gain-corrected (dimensionless), NaN where missing.
    sphere, F, D : the scan's grid and the dish (m).
    grid : the aperture grid of ``delta``.
    n_rows : usable theta rows (cells wholly inside the rim image); the rest are not compared,
        nor are the last rows whose rays come from beyond the grid's outermost centres
        (:func:`solver.resample.modelled_rows`).
    correct : ``correct(misfit_on_sphere, delta) -> update`` (m): the linear inversion of an FA
        misfit, with the rim handling of the caller (zero rim change, or a rim-target refit);
        with ``fit_gain`` it returns ``(update, gain_step)``, the relative change of the scale.
    iterations : number of updates; each costs one forward run (the ideal reflector and the
        starting map cost one each, every halving of a step one more).
    forward : the forward model (:class:`solver.forward.ForwardModel`, or a plain function
        wrapped by :func:`solver.forward.as_model`); None uses the project's GO engine on
        ``device``.
    memory : depth of the Anderson acceleration (0: plain defect correction).
    weight : per-cell factor on the misfit (n_theta, n_phi), dimensionless; None for 1.
    fit_gain : estimate the scan's scale with the surface (see the module docstring).
    progress : ``progress(stage, fraction)`` over the whole refinement (fraction 0..1); the
        model reports within each of its calls.
    noise_variance : the relative variance v of the scan's noise (its FA's, per cell); the
        misfit's noise floor sqrt(v mean(weight^2)) is what no update can remove, so a shortened
        step is asked to remove its share of the misfit above that floor only.
    """
    start = time.perf_counter()
    model = as_model(forward) if forward is not None else go_forward(device)
    history = RefineHistory()
    if iterations <= 0:
        return delta, history
    report = progress or silent
    planned = iterations + 2  # forward runs without backtracking: ideal, start, one per update

    def fraction(index: int) -> float:
        """Progress fraction at the start of forward run ``index``: the planned runs share the
        range evenly, and backtracking's extra runs halve what is left, so it never goes back."""
        return index / planned if index < planned else 1.0 - 0.5 ** (index - planned + 1) / planned

    def model_of(label: str, surface: NDArray | None) -> NDArray[np.float64]:
        index = history.evaluations
        history.evaluations += 1
        report(label, fraction(index))
        return model(sphere, F, D, grid.x, grid.y, surface,
                     progress=within(report, fraction(index), fraction(index + 1), label))

    n_rows = min(n_rows, modelled_rows(sphere, F, D, grid.h))
    ideal = model_of("ideal reflector", None)
    w = 1.0 if weight is None else weight

    def misfit_of(surface: NDArray[np.float64], gamma: float, label: str) -> NDArray[np.float64]:
        """The weighted FA misfit of ``surface`` (m) at scale ``gamma``, NaN on rows not compared."""
        modelled = model_of(label, extend_outside(grid, surface))
        misfit = ((1.0 + fa_measured) * gamma - 1.0 - intensity_ratio_fa(modelled, ideal)) * w
        misfit[n_rows:] = np.nan
        return misfit

    compared = int(np.count_nonzero(np.isfinite(
        (fa_measured * np.broadcast_to(w, fa_measured.shape))[:n_rows])))

    def rms(misfit: NDArray[np.float64]) -> float:
        """RMS of the misfit over the compared cells; inf where the model leaves more than
        half of the cells the data hold dark (a map beyond the model's reach: rays crossing
        or leaving the sphere), which no step may trade for a small RMS on the rest."""
        kept = np.isfinite(misfit[:n_rows])
        if np.count_nonzero(kept) <= 0.5 * compared:
            return float("inf")
        return float(np.sqrt(np.mean(misfit[:n_rows][kept] ** 2)))

    mask = grid.mask
    floor = misfit_noise_rms(noise_variance, fa_measured, w, n_rows)
    delta = np.array(delta, dtype=np.float64, copy=True)
    gamma = 1.0
    misfit = misfit_of(delta, gamma, "starting map")
    history.misfit_rms.append(rms(misfit))
    history.gain_factor.append(gamma)
    if not np.isfinite(history.misfit_rms[-1]):
        history.stopped = ("the model of the starting (linear) map leaves most of the scan's "
                           "cells dark, so there is no misfit to correct: the linear map kept")
        report("done", 1.0)
        history.seconds = time.perf_counter() - start
        return delta, history
    # the Anderson state: the map inside the aperture and the scale, scaled to weigh little.
    # Only maps that were kept enter it, each with its own update: a rejected trial never gets
    # one, so it cannot steer later steps. The history is kept across a shortened step, for the
    # secant from the kept map to the one before tells Anderson how far the linear operator
    # overshoots (at R = 0.9 F restarting it there left 0.58 % RRMS after 3 updates, keeping it
    # 0.052 %)
    iterates: list[NDArray[np.float64]] = []
    updates: list[NDArray[np.float64]] = []
    # the share of the misfit the last kept update removed, over its length (1: as the linear
    # equation predicts); None before one is kept
    efficiency: float | None = None
    for k in range(iterations):
        step = correct(misfit, delta)
        update, gain_step = step if fit_gain else (step, 0.0)
        current = np.append(delta[mask], GAIN_SCALE * gamma)
        iterates.append(current)
        updates.append(np.append(update[mask], GAIN_SCALE * gamma * gain_step))
        iterates, updates = iterates[-(memory + 1):], updates[-(memory + 1):]
        direction = anderson_step(iterates, updates) - current
        label = f"update {k + 1}/{iterations}"
        # after an update that removed less than the sufficient decrease, the misfit is near the
        # floor the data and model allow (noise, a model coarser than the data): a rise there is
        # that floor's scatter, not an overshoot, and shorter steps fail the same test (PO data
        # of a finer quadrature: the third update rose 0.3 %, its halves fell 0.1 %)
        tries = MAX_BACKTRACKS if efficiency is None or efficiency >= SUFFICIENT_DECREASE else 0
        for halvings in range(tries + 1):
            length = 0.5**halvings
            state = current + length * direction
            trial = delta.copy()
            trial[mask] = state[:-1]
            trial_gamma = state[-1] / GAIN_SCALE if fit_gain else 1.0
            trial_misfit = misfit_of(trial, trial_gamma, label if not halvings else
                                     f"{label}, step / {2**halvings}")
            trial_rms = rms(trial_misfit)
            verdict = _compare(history.misfit_rms[-1], trial_rms, length, floor)
            if verdict != "misfit rose":
                break
        else:  # no step along this direction lowered the misfit enough: the map before it stays
            why = (f"no step shortened down to 1/{2**tries} lowered it by half the linear "
                   "prediction" if tries else
                   f"near its floor (the update before removed {100 * efficiency:.1f} %)")
            history.stopped = (f"misfit rose at update {k + 1} of {iterations}, {why}: "
                               + ("the starting (linear) map kept" if k == 0 else
                                  "the map before it kept"))
            break
        if verdict == "misfit stalled" and trial_rms > history.misfit_rms[-1]:
            # within the tolerance, but no better: the map before it stays
            history.stopped = f"misfit stalled at update {k + 1} of {iterations}: the map before it kept"
            break
        efficiency = _removed_share(history.misfit_rms[-1], trial_rms, floor) / length
        history.update_rms.append(float(np.sqrt(np.mean((trial - delta)[mask] ** 2))))
        history.backtracks.append(halvings)
        delta, gamma, misfit = trial, trial_gamma, trial_misfit
        history.misfit_rms.append(trial_rms)
        history.gain_factor.append(gamma)
        if verdict == "misfit stalled":
            history.stopped = f"misfit stalled at update {k + 1} of {iterations}"
            break
    report("done", 1.0)
    history.seconds = time.perf_counter() - start
    return delta, history


GAIN_SCALE = 1e-6  # m per unit of the scale factor in the Anderson state
#: an update that raises the misfit by more than this fraction is shortened (and rejected when
#: every shortened step does too: on grids too coarse for the data every update made the map
#: worse); one that lowers it by less ends the loop (the data no longer pull the map, while each
#: update still moved it: 50 iterations drifted 3.4 -> 20.7 um RMS on a 64-point grid)
MISFIT_TOLERANCE = 1e-3
#: how many times a step that raised the misfit is halved before the loop gives up on it: near
#: the dish (sphere radius 0.85 F and beyond) the terms the linear equation drops make the full
#: step overshoot, and half of it converges
MAX_BACKTRACKS = 3
#: a shortened step of length t (0 < t < 1) is kept only when it lowers the misfit by at least
#: this share of the fraction t the linear equation predicts (Armijo's sufficient decrease):
#: near the dish (R = 0.85 to 0.97 F) the first kept shortened step removed 58 to 73 % of the
#: misfit; on a 16-point grid, too coarse for the paper's surface, half a step removed 11 %, and
#: the updates that followed took the map from 240 to 697 um RMS error (the linear answer stays)
SUFFICIENT_DECREASE = 0.5


def _removed_share(before: float, now: float, floor: float = 0.0) -> float:
    """The share of the misfit above the noise ``floor`` that a step took ``before`` -> ``now``
    away (RMS values); a misfit at or under the floor has nothing to remove: 0."""
    excess = before - floor
    return (before - now) / excess if excess > 0 else 0.0


def _compare(before: float, now: float, length: float = 1.0, floor: float = 0.0) -> str:
    """How the misfit ``now`` of a trial map, a step of ``length`` (1: the full update) from
    the map of misfit ``before``, compares with it: "misfit rose" (or, for a shortened step, fell
    by less than :data:`SUFFICIENT_DECREASE` of its share ``length`` of the misfit above the
    noise ``floor``, which no step removes), "misfit stalled" (within the tolerance) or "" (it
    fell). (Against the whole misfit, 0.0005 dB of noise near the dish, R = 0.95 F, made the
    halved steps, which removed 6 % of a misfit mostly noise, fail the test: the linear map was
    returned, 69 to 116 um off where noise-free data gave 3 um.)"""
    if now > before * (1.0 + MISFIT_TOLERANCE):
        return "misfit rose"
    if length < 1.0 and before > floor and now > before - SUFFICIENT_DECREASE * length * (before - floor):
        return "misfit rose"
    if now > before * (1.0 - MISFIT_TOLERANCE):
        return "misfit stalled"
    return ""


def anderson_step(iterates: list[NDArray[np.float64]],
                  updates: list[NDArray[np.float64]]) -> NDArray[np.float64]:
    """Next iterate from the last iterates x_i and their updates f_i (Anderson, type II).

    Minimises |f_k - dF gamma| over gamma, with dF, dX the differences of successive f and x,
    and returns x_k + f_k - (dX + dF) gamma; with one pair it is x_k + f_k.
    """
    x, f = iterates[-1], updates[-1]
    if len(iterates) == 1:
        return x + f
    dF = np.stack([b - a for a, b in pairwise(updates)], axis=1)
    dX = np.stack([b - a for a, b in pairwise(iterates)], axis=1)
    gamma, *_ = np.linalg.lstsq(dF, f, rcond=None)
    return x + f - (dX + dF) @ gamma
