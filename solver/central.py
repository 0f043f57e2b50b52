"""The central mode: what a blocked centre of the aperture leaves unobservable.

Frame and units (docs/physics.md): aperture x, y and r in m, delta in m, a = D/2. A feed cabin
or subreflector hides the middle of the aperture: the scan's first theta rows are blocked
(``Scan.blocked``), so the data say nothing about FA = G Laplacian(delta) for r < r_h (the
radius those rows map to, r = 2F tan(theta/2)). Any delta whose Laplacian lives inside that
disk and which is zero on the rim then goes unseen by the linear equation; outside the disk
its leading part is the monopole c log(r / a), harmonic on the observed annulus and zero on the
rim, which the inpainted hole fixes only by chance (tens of micrometres on the paper's dish).
Higher multipoles fall off as (r_h / r)^n and are left.

The linear equation's unobservable shape is :func:`log_mode`: the Poisson solution of a
uniform source on the hidden disk (total flux 2 pi), zero on the rim, log(r / a) for r >= r_h
and log(r_h / a) + (r^2 - r_h^2) / (2 r_h^2) inside (smooth across r_h, finite at the centre).
The exact GO model is not quite blind to it: its rays shift on the sphere (the term the
paper's equation drops), so it answers to the log mode weakly, and the refinement, which
cannot produce the mode, explains that answer with other shapes. What the refined map fixes
only up to a multiple of is the model's own null shape near the log mode: :func:`model_mode`
finds it (the log mode minus the part of its answer the GO inversion can explain, by the
refinement's own defect correction with Anderson acceleration; a few more model calls).

Like piston, tilt and focus when they are removed, the inversion then fits that shape over
the observed annulus r >= r_h by least squares and removes it (jointly with delta_c when the
gain is estimated: :mod:`solver.unobservable`), records its coefficient c (m) and says the
mode is unobservable; the truth gets the same removal before the RMS. Inside the
hidden disk the map is NaN: nothing was measured there (and the RMS skips it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from raysim.progress import Progress
from solver.aperture import ApertureGrid
from solver.equation import intensity_ratio_fa
from solver.forward import ForwardModel
from solver.nonlinear import Correct, anderson_step, extend_outside

MODE_ITERATIONS = 3  # defect-correction steps of the model's null shape (converged by 2 to 3)
MODE_STEP = 3e-5     # m per unit of the mode in the model's finite difference: linear, above round-off


@dataclass(frozen=True)
class CentralMode:
    """The shape a hidden centre of radius ``r_h`` (m) leaves unobservable, on the aperture
    grid (dimensionless, NaN outside), and how it was found (``log`` or ``model``)."""

    r_h: float
    shape: NDArray[np.float64]
    kind: str

    def blank(self, grid: ApertureGrid, delta: NDArray[np.float64]) -> NDArray[np.float64]:
        """``delta`` with NaN at r < r_h: the hidden centre holds no data, and what the solve put
        there (the inpainted FA's answer) is no measurement."""
        return np.where(grid.r < self.r_h, np.nan, delta)

    def attrs(self, c: float) -> dict:
        """The SurfaceMap attributes of the removed mode with coefficient ``c`` (m)."""
        shape = ("c log(r/a) on the annulus (smooth inside), zero on the rim" if self.kind == "log"
                 else "the refinement model's null shape next to c log(r/a) (zero on the rim)")
        return {"central_hole_radius_m": self.r_h, "removed_central_mode_m": c,
                "central_mode": f"unobservable: the blocked centre r < central_hole_radius_m leaves "
                                f"{shape}; fitted over r >= central_hole_radius_m and removed from "
                                "the map (and from the truth before the RMS)",
                "central_mode_shape": self.kind, "central_mode_observable": False,
                "central_hole": "no data: the map is NaN at r < central_hole_radius_m",
                "rms_definition": "over the grid points with central_hole_radius_m <= r < D/2 "
                                  "(the hidden centre holds no data)"}


def hole_radius(blocked: NDArray[np.bool_] | None, theta_edges: NDArray[np.float64],
                F: float) -> float | None:
    """The radius r_h (m) on the aperture of the blocked centre: the leading theta rows whose
    cells are all blocked, mapped by r = 2F tan(theta/2) from their outer edge; None when the
    first row is not wholly blocked (``blocked`` (n_theta, n_phi), ``theta_edges`` in rad)."""
    if blocked is None or not blocked.shape[0] or not blocked[0].all():
        return None
    rows = np.all(blocked, axis=1)
    n = int(np.argmin(rows)) if not rows.all() else len(rows)
    return float(2.0 * F * np.tan(0.5 * theta_edges[n]))


def log_mode(grid: ApertureGrid, r_h: float) -> NDArray[np.float64]:
    """The linear equation's unobservable shape (dimensionless, NaN outside the aperture) for a
    hidden disk of radius ``r_h`` (m): see the module docstring."""
    a, r = grid.a, grid.r
    inside = np.log(r_h / a) + (r * r - r_h * r_h) / (2.0 * r_h * r_h)
    mode = np.where(r >= r_h, np.log(np.maximum(r, r_h) / a), inside)
    return grid.masked(mode)


def model_mode(log: NDArray[np.float64], delta: NDArray[np.float64], model: ForwardModel,
               correct: Correct, sphere, F: float, D: float, grid: ApertureGrid,
               observed: NDArray[np.bool_], weight: NDArray[np.float64] | None = None,
               iterations: int = MODE_ITERATIONS, step: float = MODE_STEP,
               progress: Progress | None = None) -> NDArray[np.float64]:
    """The model's null shape next to ``log`` at the estimate ``delta`` (m): u with J u = 0 on
    the ``observed`` sphere cells (J the model's FA response, by finite differences of ``step``
    m), found as the fixed point of u <- u - correct(J u) from u = ``log`` (the refinement's
    preconditioner ``correct``, Anderson-accelerated). One model call more than ``iterations``;
    ``weight`` (per cell) as the refinement's misfits."""
    report = progress or (lambda stage, fraction: None)
    mask = grid.mask
    w = 1.0 if weight is None else weight
    ideal = model(sphere, F, D, grid.x, grid.y, None)

    def fa(d: NDArray[np.float64]) -> NDArray[np.float64]:
        return intensity_ratio_fa(model(sphere, F, D, grid.x, grid.y, extend_outside(grid, d)), ideal)

    report("central mode", 0.0)
    base = fa(delta)
    u = np.array(log, dtype=np.float64, copy=True)
    iterates: list[NDArray[np.float64]] = []
    updates: list[NDArray[np.float64]] = []
    for k in range(iterations):
        report("central mode", (k + 1) / (iterations + 1))
        response = (fa(delta + step * np.nan_to_num(u)) - base) / step * w
        response[~observed] = np.nan
        out = correct(response, delta)
        update = out[0] if isinstance(out, tuple) else out
        iterates.append(u[mask].copy())
        updates.append(-update[mask])
        u = u.copy()
        u[mask] = anderson_step(iterates[-4:], updates[-4:])
    report("central mode", 1.0)
    return grid.masked(u)


def central_mode_of(r_h: float | None, grid: ApertureGrid, delta: NDArray[np.float64],
                    model: ForwardModel | None, correct: Correct | None, sphere, F: float, D: float,
                    observed: NDArray[np.bool_], weight: NDArray[np.float64] | None = None,
                    progress: Progress | None = None) -> CentralMode | None:
    """The :class:`CentralMode` of a hidden centre of radius ``r_h`` (None: no hidden centre,
    None back): the model's null shape when a refinement ran (``model`` and its ``correct``),
    else the log mode of the linear answer."""
    if r_h is None:
        return None
    log = log_mode(grid, r_h)
    if model is None or correct is None:
        return CentralMode(r_h, log, "log")
    shape = model_mode(log, delta, model, correct, sphere, F, D, grid, observed, weight,
                       progress=progress)
    return CentralMode(r_h, shape, "model")
