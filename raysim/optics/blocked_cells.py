"""The probe-sphere cells that obstacles hide, from a GO trace of the ideal dish.

Frame and units of docs/physics.md (reflector frame, metres; sphere of radius R about the focus). The
blocked share of a cell is the power of the GO tubes that obstacles removed over the power the
clear dish sends it (:func:`raysim.optics.blockage.blocked_share`); the FieldMaps of every engine
record it (:func:`raysim.optics.blockage.fieldmap_variables`). These traces sit above the GO
engine, which itself shadows its tubes with :mod:`raysim.optics.blockage`: kept apart from that
module so the obstacle tests stay below the engines that use them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.maps.probe import Probe
from raysim.maps.sphere import SphereGrid
from raysim.optics import go
from raysim.optics.blockage import BLOCKAGE_RAY_SPACING
from raysim.surface.obstacles import ObstacleMesh


def ideal_blocked_share(ideal, grid: SphereGrid, direction: ArrayLike, device: str | None = "cpu",
                        spacing: float = BLOCKAGE_RAY_SPACING) -> NDArray[np.float64]:
    """The blocked share (n_theta, n_phi) of the GO tubes of ``ideal`` (a Reflector with
    obstacles), rays about ``spacing`` (m) apart: what the wave engines' FieldMaps record."""
    result = go.trace(ideal, grid, direction, go.ray_subdivisions(ideal, spacing), device)
    return result.blocked_share


def paraboloid_blocked_share(grid: SphereGrid, F: float, D: float, obstacles: ObstacleMesh,
                             probe: Probe | None = None, polarization: float = 0.0,
                             device: str | None = "cpu") -> NDArray[np.float64]:
    """The blocked share (n_theta, n_phi) of the ideal paraboloid (F, D in m) with ``obstacles``
    (m, reflector frame) under the on-axis wave polarised at ``polarization`` (rad from x), as
    ``probe`` reads it (None: the ideal meter), traced as the inversion's GO model traces it
    (:class:`raysim.optics.go.ParaboloidTracer`: its mesh and ray lattice). A measured scan,
    which has no scene, so marks the cells a GO scene of the same dish marks (at the scene's
    default mesh and subdivisions: the same tubes)."""
    tracer = go.ParaboloidTracer(device, obstacles=obstacles).tracer(grid, F, D)
    e_hat = (np.cos(polarization), np.sin(polarization), 0.0)
    return tracer.trace(tracer.template, None, probe, e_hat).blocked_share
