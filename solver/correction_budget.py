"""The command error each actuator inherits from a scan's error budget (:mod:`solver.budget`).

The budget writes the map's error as independent random coefficients of the disk's unit-norm
Dirichlet modes phi_mn (the readings' noise and the drift references, per mode: a mean square
over the disk, so a coefficient variance of mean square x area / phases) plus, with rim targets,
the harmonic fit's error: independent coefficients of (r / a)^m cos / sin (m phi) of variance
s^2 / N (m = 0) and 2 s^2 / N (m >= 1) for N targets of std s. The commands are linear in the
map, c = L delta (:func:`solver.correction.correct` without stroke limits: the ``remove`` terms
taken off and refitted with the commands, :class:`solver.correction.JointFit`), so each
actuator's variance is
sum_k var_k (L f_k)^2 over those shapes f_k. The share along delta_c, which an estimated gain
removes from the map, is kept here: an upper bound (a radial shape, mostly focus-like).
Frame and units: aperture plane (x, y) in m, maps and commands in m.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.typing import NDArray
from scipy.special import jn_zeros, jv

from solver.actuators import ActuatorLayout
from solver.correction import JointFit, influence_matrix, panel_ids, term_columns
from solver.fit import remove_terms


class DiskModes:
    """The disk's Dirichlet modes on one aperture grid, sharing the grid's radii.

    J_m of high order costs tens of microseconds per point, and a budget asks for thousands of
    modes; a square grid centred on the axis holds each radius about eight times (its
    symmetries), so the Bessel function is taken once per distinct radius inside the disk."""

    def __init__(self, grid) -> None:
        X, Y = grid.XY
        r = np.hypot(X, Y)
        self.a = float(grid.a)
        self.inside = r <= self.a
        self.radii, self.index = np.unique(r[self.inside], return_inverse=True)
        self.phi = np.arctan2(Y, X)[self.inside]

    def mode(self, m: int, n: int, phase: int) -> NDArray[np.float64]:
        """The unit-norm (over the disk r <= a, m^2) Dirichlet mode J_m(j_mn r / a) cos(m phi)
        (phase 0) or sin (phase 1) on the grid (1/m), 0 outside the disk."""
        a = self.a
        j = float(jn_zeros(m, n)[n - 1])
        norm = np.sqrt(0.5 * a * a * jv(m + 1, j) ** 2 * (2.0 * np.pi if m == 0 else np.pi))
        ang = np.cos(m * self.phi) if phase == 0 else np.sin(m * self.phi)
        out = np.zeros(self.inside.shape)
        out[self.inside] = jv(m, j * self.radii / a)[self.index] * ang / norm
        return out


def dirichlet_mode(grid, m: int, n: int, phase: int) -> NDArray[np.float64]:
    """One Dirichlet mode on ``grid`` (see :meth:`DiskModes.mode`)."""
    return DiskModes(grid).mode(m, n, phase)


def budget_shapes(grid, modes: Iterable[tuple[int, int, float]],
                  rim_targets: int = 0, target_std: float = 0.0, max_harmonics: int = 12):
    """(shape on the grid, coefficient variance) pairs of the map error: ``modes`` as (m, n,
    mean square over the disk in m^2, both phases), the rim fit's harmonics (see the module)."""
    area = np.pi * grid.a**2
    disk = DiskModes(grid)
    for m, n, ms in modes:
        phases = 1 if m == 0 else 2
        for phase in range(phases):
            yield disk.mode(m, n, phase), ms * area / phases
    if rim_targets:
        X, Y = grid.XY
        rho, phi = np.hypot(X, Y) / grid.a, np.arctan2(Y, X)
        order = min(max_harmonics, (rim_targets - 1) // 2)
        v = target_std**2 / rim_targets
        yield np.ones_like(rho), v
        for m in range(1, order + 1):
            yield rho**m * np.cos(m * phi), 2.0 * v
            yield rho**m * np.sin(m * phi), 2.0 * v


def command_std_from_budget(grid, layout, actuators: ActuatorLayout, remove: tuple[str, ...],
                            shapes) -> NDArray[np.float64]:
    """Standard deviation (m) of each actuator's command from the map error ``shapes`` ((grid
    shape, coefficient variance) pairs, :func:`budget_shapes`)."""
    ids = panel_ids(grid, np.where(grid.mask, 0.0, np.nan), layout)
    fit = JointFit(influence_matrix(grid, ids, layout, actuators), term_columns(grid, ids, remove)[0])
    on = ids.ravel() >= 0
    var = np.zeros(actuators.n_actuators)
    for shape, v in shapes:
        kept, _ = remove_terms(grid, np.where(ids >= 0, shape, np.nan), remove)
        c = fit.least_norm(kept.ravel()[on])
        var += v * c * c
    return np.sqrt(var)
