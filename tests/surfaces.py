"""Independent surface helpers shared by the tests: the RMS of a deformation over the disk, and
a smooth illumination taper (no edge, so no edge diffraction).

A polar midpoint quadrature (area-weighted, nothing shared with raysim's aperture grid or its
panel sampling), each point evaluated on the panel under it.
"""

from __future__ import annotations

import numpy as np


def disk_rms(deformation, a: float, layout=None, panels_only: bool = False,
             n_r: int = 600, n_phi: int = 900) -> float:
    """RMS (m) of delta over the disk r < a (m); with ``panels_only`` over the panels' footprints
    alone (the gaps of ``layout`` left out rather than counted as zero)."""
    r = (np.arange(n_r) + 0.5) / n_r * a
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
    R, P = np.meshgrid(r, phi)
    x, y = R * np.cos(P), R * np.sin(P)
    panel = layout.panel_at(x, y) if layout is not None else None
    values = deformation(x, y, panel)
    weight = R if not panels_only else np.where(panel >= 0, R, 0.0)
    return float(np.sqrt(np.sum(values**2 * weight) / np.sum(weight)))


def smooth_taper(r0: float, r1: float):
    """Weight 1 for r <= r0 falling to 0 at r1 through a C-infinity step (no edge to diffract)."""

    def f(u):
        return np.where(u > 0, np.exp(-1.0 / np.maximum(u, 1e-300)), 0.0)

    def taper(x, y):
        t = np.clip((r1 - np.hypot(x, y)) / (r1 - r0), 0.0, 1.0)
        return f(t) / (f(t) + f(1.0 - t))

    return taper
