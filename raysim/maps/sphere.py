"""The probe hemisphere: its (theta, phi) cell grid and the ideal GO relations on it.

Frame (docs/physics.md): reflector vertex at the origin, axis +z, focus at (0, 0, F). The sphere
of radius R is centred at the focus; theta is the angle between (P - focus) and -z (theta = 0
looks at the vertex), phi = atan2(y, x) of (P - focus). All angles in radians, lengths in
metres. Cell centres sit at theta_i = theta_min + (i + 1/2) dtheta, phi_j = phi_min +
(j + 1/2) dphi.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

HALF_PI = 0.5 * np.pi
TWO_PI = 2.0 * np.pi


def theta_rim(D: float, F: float) -> float:
    """Angle (rad) at which the focus sees the rim of a dish of diameter D, focal length F."""
    return 2.0 * np.arctan(D / (4.0 * F))


def aperture_radius(theta: ArrayLike, F: float) -> NDArray[np.float64]:
    """Ideal GO mapping sphere -> aperture, r = 2 F tan(theta / 2) (m)."""
    return 2.0 * F * np.tan(0.5 * np.asarray(theta, dtype=np.float64))


def theta_of_radius(r: ArrayLike, F: float) -> NDArray[np.float64]:
    """Inverse of :func:`aperture_radius`: theta = 2 atan(r / 2F) (rad)."""
    return 2.0 * np.arctan(np.asarray(r, dtype=np.float64) / (2.0 * F))


def rho(theta: ArrayLike, F: float) -> NDArray[np.float64]:
    """Distance focus -> ideal paraboloid along direction theta, rho = 2F / (1 + cos theta) (m)."""
    return 2.0 * F / (1.0 + np.cos(np.asarray(theta, dtype=np.float64)))


def ideal_go_intensity(theta: ArrayLike, F: float, R: float, D: float | None = None):
    """Point value of the ideal paraboloid's GO intensity on the sphere, (rho / R)^2.

    Relative to the incident plane wave's intensity. With ``D`` given, directions beyond the
    rim image (theta > theta_rim) get 0.
    """
    theta = np.asarray(theta, dtype=np.float64)
    value = (rho(theta, F) / R) ** 2
    if D is not None:
        value = np.where(theta <= theta_rim(D, F), value, 0.0)
    return value


def ideal_go_cell_mean(theta_lo, theta_hi, F: float, R: float, D: float | None = None):
    """Mean of (rho / R)^2 over sphere cells theta_lo..theta_hi (power through the cell / area).

    Exact: the integral of (2F / (R (1 + cos t)))^2 sin t dt is (4F^2 / R^2) / (1 + cos t).
    With ``D`` given, the part of a cell beyond the rim image contributes no power.
    """
    a = np.asarray(theta_lo, dtype=np.float64)
    b = np.asarray(theta_hi, dtype=np.float64)
    # the lit part of the cell ends at the rim image; a cell wholly beyond it gets none
    b_lit = b if D is None else np.minimum(b, np.maximum(a, theta_rim(D, F)))
    power = (4.0 * F * F / (R * R)) * (1.0 / (1.0 + np.cos(b_lit)) - 1.0 / (1.0 + np.cos(a)))
    return power / (np.cos(a) - np.cos(b))


@dataclass(frozen=True)
class SphereGrid:
    """Regular (theta, phi) cell grid on the sphere of radius ``radius`` (m) around the focus.

    Angles are in radians. The default covers the whole hemisphere facing the dish.
    """

    radius: float
    n_theta: int = 90
    n_phi: int = 360
    theta_min: float = 0.0
    theta_max: float = HALF_PI
    phi_min: float = 0.0
    phi_max: float = TWO_PI

    @property
    def dtheta(self) -> float:
        return (self.theta_max - self.theta_min) / self.n_theta

    @property
    def dphi(self) -> float:
        return (self.phi_max - self.phi_min) / self.n_phi

    @property
    def full_circle(self) -> bool:
        """True when the phi cells close around the axis (periodic in phi)."""
        return bool(np.isclose(self.phi_max - self.phi_min, TWO_PI))

    @property
    def theta_edges(self) -> NDArray[np.float64]:
        return np.linspace(self.theta_min, self.theta_max, self.n_theta + 1)

    @property
    def phi_edges(self) -> NDArray[np.float64]:
        return np.linspace(self.phi_min, self.phi_max, self.n_phi + 1)

    @property
    def theta(self) -> NDArray[np.float64]:
        """Cell-centre polar angles (rad), shape (n_theta,)."""
        return self.theta_min + (np.arange(self.n_theta) + 0.5) * self.dtheta

    @property
    def phi(self) -> NDArray[np.float64]:
        """Cell-centre azimuths (rad), shape (n_phi,)."""
        return self.phi_min + (np.arange(self.n_phi) + 0.5) * self.dphi

    def cell_area(self) -> NDArray[np.float64]:
        """Area of each cell on the sphere (m^2), shape (n_theta, n_phi)."""
        e = self.theta_edges
        band = self.radius**2 * (np.cos(e[:-1]) - np.cos(e[1:])) * self.dphi
        return np.repeat(band[:, None], self.n_phi, axis=1)

    def directions(self) -> NDArray[np.float64]:
        """Unit vectors from the focus to the cell centres, shape (n_theta, n_phi, 3)."""
        t, p = np.meshgrid(self.theta, self.phi, indexing="ij")
        s = np.sin(t)
        return np.stack([s * np.cos(p), s * np.sin(p), -np.cos(t)], axis=-1)

    def points(self, F: float) -> NDArray[np.float64]:
        """Cell-centre positions in the reflector frame (m), shape (n_theta, n_phi, 3)."""
        return np.array([0.0, 0.0, F]) + self.radius * self.directions()

    @classmethod
    def from_centres(cls, theta: ArrayLike, phi: ArrayLike, radius: float) -> SphereGrid:
        """Rebuild the grid from regular cell centres (as a FieldMap stores them)."""
        theta = np.asarray(theta, dtype=np.float64)
        phi = np.asarray(phi, dtype=np.float64)
        dt = (theta[-1] - theta[0]) / (len(theta) - 1) if len(theta) > 1 else 2 * theta[0]
        dp = (phi[-1] - phi[0]) / (len(phi) - 1) if len(phi) > 1 else TWO_PI
        return cls(
            radius=float(radius),
            n_theta=len(theta),
            n_phi=len(phi),
            theta_min=float(theta[0] - 0.5 * dt),
            theta_max=float(theta[-1] + 0.5 * dt),
            phi_min=float(phi[0] - 0.5 * dp),
            phi_max=float(phi[-1] + 0.5 * dp),
        )
