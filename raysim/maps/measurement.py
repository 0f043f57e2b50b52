"""What a probe on the rig measures besides the field: where it really is, and slow drift.

Pure functions shared by the simulated rig (:mod:`hardware.sim`) and a dataset's measurement
effects (:mod:`raysim.dataset.effects`). Frame of docs/physics.md: angles in rad from the focus
(theta from -z, phi = atan2(y, x)), lengths in m, gains in dB.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def probe_point(theta: ArrayLike, phi: ArrayLike, radius: float,
                centre_offset: ArrayLike = (0.0, 0.0, 0.0)) -> tuple[NDArray, NDArray, NDArray]:
    """Where a probe really is, seen from the focus: (theta', phi' in [0, 2 pi), r) (rad, m).

    The track of radius ``radius`` puts the probe at direction (theta, phi) from the track's
    centre, and that centre sits at ``centre_offset`` (x, y, z in m) from the focus.
    """
    theta = np.asarray(theta, dtype=np.float64)
    phi = np.asarray(phi, dtype=np.float64)
    c = np.asarray(centre_offset, dtype=np.float64)
    st = np.sin(theta)
    px = c[0] + radius * st * np.cos(phi)
    py = c[1] + radius * st * np.sin(phi)
    pz = c[2] - radius * np.cos(theta)
    return (np.arctan2(np.hypot(px, py), -pz), np.mod(np.arctan2(py, px), 2.0 * np.pi),
            np.sqrt(px * px + py * py + pz * pz))


def drift_db(amplitude_db: float, period: float, phase: float, index: ArrayLike) -> NDArray:
    """Slow receiver/source gain drift (dB) at acquisition step ``index`` (0 at step 0):
    A (sin(2 pi n / P + p) - sin p), a sinusoid of ``period`` P steps and phase p (rad)."""
    n = np.asarray(index, dtype=np.float64)
    return amplitude_db * (np.sin(2.0 * np.pi * n / period + phase) - np.sin(phase))


def serpentine_order(n_theta: int, n_phi: int) -> NDArray[np.int64]:
    """Acquisition step of each (theta, phi) cell, (n_theta, n_phi): one sweep in theta per phi
    line, phi ascending, the sweep direction alternating (the rig's order, references left out)."""
    i = np.arange(n_theta)[:, None]
    j = np.arange(n_phi)[None, :]
    return j * n_theta + np.where(j % 2 == 0, i, n_theta - 1 - i)
