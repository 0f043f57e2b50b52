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
from solver.equation import intensity_ratio_fa
from solver.forward import Forward, ForwardModel, as_model, go_forward
from solver.resample import modelled_rows

__all__ = ["Correct", "Forward", "ForwardModel", "RefineHistory", "anderson_step", "extend_outside",
           "go_forward", "outside_fill", "refine"]


@dataclass
class RefineHistory:
    """Per iteration: RMS of the update (m), of the weighted FA misfit on the usable cells, and
    the scale factor gamma on the measured 1 + FA (1 unless the gain is fitted; one more entry
    than iterations: the last is the final value)."""

    update_rms: list[float] = field(default_factory=list)
    misfit_rms: list[float] = field(default_factory=list)
    gain_factor: list[float] = field(default_factory=list)
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
           progress: Progress | None = None) -> tuple[NDArray[np.float64], RefineHistory]:
    """Refine ``delta`` (m, (N, N)) by defect correction against the measured FA on the sphere.

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
    iterations : number of forward evaluations and updates.
    forward : the forward model (:class:`solver.forward.ForwardModel`, or a plain function
        wrapped by :func:`solver.forward.as_model`); None uses the project's GO engine on
        ``device``.
    memory : depth of the Anderson acceleration (0: plain defect correction).
    weight : per-cell factor on the misfit (n_theta, n_phi), dimensionless; None for 1.
    fit_gain : estimate the scan's scale with the surface (see the module docstring).
    progress : ``progress(stage, fraction)`` over the whole refinement (fraction 0..1); the
        model reports within each of its calls.
    """
    start = time.perf_counter()
    model = as_model(forward) if forward is not None else go_forward(device)
    history = RefineHistory()
    if iterations <= 0:
        return delta, history
    report = progress or silent
    n_calls = iterations + 1

    def model_of(index: int, label: str, surface: NDArray | None) -> NDArray[np.float64]:
        report(label, index / n_calls)
        return model(sphere, F, D, grid.x, grid.y, surface,
                     progress=within(report, index / n_calls, (index + 1) / n_calls, label))

    n_rows = min(n_rows, modelled_rows(sphere, F, D, grid.h))
    ideal = model_of(0, "ideal reflector", None)
    w = 1.0 if weight is None else weight
    delta = np.array(delta, dtype=np.float64, copy=True)
    mask = grid.mask
    gamma = 1.0
    iterates: list[NDArray[np.float64]] = []
    updates: list[NDArray[np.float64]] = []
    evaluated = (delta, gamma)  # the last map (and scale) whose misfit was measured
    for k in range(iterations):
        modelled = model_of(k + 1, f"iteration {k + 1}/{iterations}",
                            extend_outside(grid, delta))
        history.gain_factor.append(gamma)
        misfit = ((1.0 + fa_measured) * gamma - 1.0 - intensity_ratio_fa(modelled, ideal)) * w
        misfit[n_rows:] = np.nan
        history.misfit_rms.append(float(np.sqrt(np.nanmean(misfit[:n_rows] ** 2))))
        if k and (ended := _misfit_ended(history.misfit_rms)):
            history.stopped = f"{ended} at iteration {k + 1} of {iterations}"
            if ended == "misfit rose":  # the previous map fitted the data better: keep it
                delta, gamma = evaluated
                history.misfit_rms.pop()
                history.gain_factor.pop()
            break
        evaluated = (delta, gamma)
        step = correct(misfit, delta)
        update, gain_step = step if fit_gain else (step, 0.0)
        update = update[mask]
        history.update_rms.append(float(np.sqrt(np.mean(update**2))))
        # the scale rides along as one more unknown, scaled to weigh little in Anderson's fit
        iterates.append(np.append(delta[mask], GAIN_SCALE * gamma))
        updates.append(np.append(update, GAIN_SCALE * gamma * gain_step))
        iterates, updates = iterates[-(memory + 1):], updates[-(memory + 1):]
        following = anderson_step(iterates, updates)
        delta = delta.copy()
        delta[mask] = following[:-1]
        gamma = following[-1] / GAIN_SCALE if fit_gain else 1.0
    history.gain_factor.append(gamma)
    report("done", 1.0)
    history.seconds = time.perf_counter() - start
    return delta, history


GAIN_SCALE = 1e-6  # m per unit of the scale factor in the Anderson state
#: the refinement stops when an iteration raises the misfit by more than this fraction (the map
#: before it is returned: on grids too coarse for the data every update made it worse), or
#: lowers it by less (the data no longer pull the map, while each update still moved it: 50
#: iterations drifted 3.4 -> 20.7 um RMS on a 64-point grid)
MISFIT_TOLERANCE = 1e-3


def _misfit_ended(misfit_rms: list[float]) -> str:
    """Why the refinement should stop after the last misfit of ``misfit_rms``, or ""."""
    before, now = misfit_rms[-2], misfit_rms[-1]
    if now > before * (1.0 + MISFIT_TOLERANCE):
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
