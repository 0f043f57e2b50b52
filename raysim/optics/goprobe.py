"""What a probe reads of GO ray tubes: each tube's power weighted by the probe's response.

Frame and units (docs/physics.md): reflector frame, metres, radians; the sphere of radius R
about the focus. A ray of the incident plane wave (direction k, unit polarisation e_i) meets
the reflector at a point of unit normal n and leaves along r = k - 2 (k . n) n with the
polarisation a perfect conductor gives it, e_r = 2 (n . e_i) n - e_i (unit, transverse to r);
both hold along the straight ray to the sphere. Where the ray enters the sphere (unit vector u
from the focus), the probe's boresight is -u (it faces the dish, its axis on the radius) and it
reads g(alpha) (p_t . e_r)^2 of the ray's intensity (:meth:`raysim.maps.probe.Probe.weight`).

A tube's weight is the mean of its three rays' weights (the response varies smoothly across a
tube, so the mean is its average over the tube to second order in the tube's size): the tube
deposits its power times that weight, and a cell then holds the probe's reading averaged over
the cell, as the intensity is for the ideal meter.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from raysim.maps.probe import Probe


def entry_directions(chart: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit vectors u (N, 3) from the focus to the sphere entry points, from their Lambert
    chart coordinates X (N, 2) about -z (:mod:`raysim.optics.kernels.go`):
    |X|^2 = 2 (1 + u_z) and (u_x, u_y) = X sqrt((1 - u_z) / 2)."""
    X = np.asarray(chart, dtype=np.float64)
    uz = np.clip(0.5 * np.sum(X * X, axis=1) - 1.0, -1.0, 1.0)
    s = np.sqrt(0.5 * (1.0 - uz))
    return np.column_stack([X[:, 0] * s, X[:, 1] * s, uz])


def ray_weights(probe: Probe, normals: NDArray[np.float64], k_hat: NDArray[np.float64],
                e_hat: NDArray[np.float64], chart: NDArray[np.float64],
                ok: NDArray[np.bool_]) -> NDArray[np.float64]:
    """The probe's reading per unit intensity of each ray (N,): ``normals`` (N, 3) unit surface
    normals at the hits, ``k_hat`` and ``e_hat`` the incident wave's direction and unit
    polarisation, ``chart`` (N, 2) the rays' sphere entries, ``ok`` (N,) the rays that reached
    the sphere (the others weigh 0)."""
    n = np.asarray(normals, dtype=np.float64)
    r = k_hat - 2.0 * (n @ k_hat)[:, None] * n
    e = 2.0 * (n @ e_hat)[:, None] * n - e_hat
    w = probe.weight(r, -entry_directions(chart), e)
    return np.where(ok, w, 0.0)


def tube_weights(probe: Probe, tubes: NDArray[np.int32], normals: NDArray[np.float64],
                 k_hat: NDArray[np.float64], e_hat: NDArray[np.float64],
                 chart: NDArray[np.float64], ok: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Each tube's weight (T,): the mean of its three rays' :func:`ray_weights`."""
    return ray_weights(probe, normals, k_hat, e_hat, chart, ok)[tubes].mean(axis=1)
