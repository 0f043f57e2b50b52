"""Boundary data on the rim r = D/2: the paper's zero, or rim targets from a CSV ``x,y,dz`` (m).

Frame (docs/physics.md): aperture plane x, y (m), phi = atan2(y, x) (rad), dz along z (m).

The interior intensity data fix delta only up to a harmonic function (Laplacian zero: piston,
tilt, astigmatism, any r^n cos(n phi)), which the rim values decide. Rim targets measured by a
laser tracker or photogrammetry pin it down: given a current estimate delta_k, the misfit
dz - delta_k at the targets is fitted by least squares with the harmonic polynomials

    h(r, phi) = c_0 + sum_{k=1..K} (r/a)^k (c_k cos k phi + s_k sin k phi),   a = D/2,

which are exactly harmonic, so targets a little inside or outside the rim are used where they
are. The rim values of h, h(a, phi), are a truncated Fourier series in phi: periodic, smooth,
and the Dirichlet values the Poisson solve takes. K is at most ``max_harmonics``, at most
(n - 1) / 2 for n targets, and small enough that the widest angular gap between targets is
resolved (K <= pi / gap).
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from solver.errors import RimTargetsError

MIN_TARGETS = 8
MAX_HARMONICS = 12
MAX_RADIUS_FACTOR = 1.05  # targets may sit up to 5 % beyond the rim
MIN_RADIUS_FACTOR = 0.8  # ... and up to 20 % inside it: they fix the rim values


@dataclass(frozen=True)
class RimTargets:
    """Surface points near the rim: x, y (m) in the aperture plane, dz (m) along z."""

    x: NDArray[np.float64]
    y: NDArray[np.float64]
    dz: NDArray[np.float64]
    source: str = "rim targets"

    def __len__(self) -> int:
        return int(self.x.size)

    @property
    def phi(self) -> NDArray[np.float64]:
        return np.mod(np.arctan2(self.y, self.x), 2.0 * np.pi)

    @property
    def r(self) -> NDArray[np.float64]:
        return np.hypot(self.x, self.y)


@dataclass(frozen=True)
class RimSeries:
    """Harmonic function h(r, phi) with Fourier coefficients on the rim radius ``a`` (m).

    ``cos`` (K+1,) holds c_0..c_K and ``sin`` (K+1,) holds 0, s_1..s_K, all in m.
    """

    a: float
    cos: NDArray[np.float64]
    sin: NDArray[np.float64]

    @property
    def order(self) -> int:
        return self.cos.size - 1

    def __call__(self, phi, r=None) -> NDArray[np.float64]:
        """h at azimuth phi (rad) and radius r (m; the rim when None), in m."""
        phi = np.asarray(phi, dtype=np.float64)
        rho = np.ones_like(phi) if r is None else np.asarray(r, dtype=np.float64) / self.a
        k = np.arange(self.order + 1)
        power = rho[..., None] ** k
        return np.sum(power * (self.cos * np.cos(k * phi[..., None])
                               + self.sin * np.sin(k * phi[..., None])), axis=-1)

    def __add__(self, other: RimSeries) -> RimSeries:
        k = max(self.order, other.order) + 1
        pad = lambda c: np.pad(c, (0, k - c.size))  # noqa: E731
        return RimSeries(self.a, pad(self.cos) + pad(other.cos), pad(self.sin) + pad(other.sin))


def read_rim_csv(path: str | os.PathLike[str]) -> RimTargets:
    """Read rim targets from a CSV with header ``x,y,dz`` (metres); one target per row.

    Raises :class:`RimTargetsError` naming the file and row of the first defect.
    """
    path = Path(path)
    if not path.is_file():
        raise RimTargetsError(f"{path}: no such rim-target file")
    try:
        # utf-8-sig: a spreadsheet's byte-order mark is not part of the header
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = [row for row in csv.reader(fh) if row and not row[0].lstrip().startswith("#")]
    except (OSError, UnicodeDecodeError) as exc:
        raise RimTargetsError(f"{path}: unreadable rim-target file ({exc})") from exc
    if not rows or [c.strip().lower() for c in rows[0]] != ["x", "y", "dz"]:
        raise RimTargetsError(f"{path}: the first line must be the header x,y,dz (metres)")
    values = []
    for number, row in enumerate(rows[1:], start=2):
        if len(row) != 3:
            raise RimTargetsError(f"{path}: row {number} has {len(row)} fields, expected x,y,dz")
        try:
            triple = [float(c) for c in row]
        except ValueError as exc:
            raise RimTargetsError(f"{path}: row {number} is not three numbers: {','.join(row)}") \
                from exc
        if not np.all(np.isfinite(triple)):
            raise RimTargetsError(f"{path}: row {number} holds a non-finite value")
        values.append(triple)
    data = np.array(values, dtype=np.float64).reshape(-1, 3)
    return RimTargets(data[:, 0], data[:, 1], data[:, 2], source=str(path))


def write_rim_csv(targets: RimTargets, path: str | os.PathLike[str]) -> None:
    """Write ``targets`` as the rim CSV :func:`read_rim_csv` reads (header x,y,dz; metres)."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(["x", "y", "dz"])
        for row in zip(targets.x, targets.y, targets.dz, strict=True):
            writer.writerow([f"{v:.9g}" for v in row])


def check_targets(targets: RimTargets, a: float) -> None:
    """Raise :class:`RimTargetsError` unless there are >= 8 targets near the rim of radius a (m):
    between 0.8 a and 1.05 a, with |dz| under 1 % of a."""
    if len(targets) < MIN_TARGETS:
        raise RimTargetsError(f"{targets.source}: {len(targets)} rim targets, at least "
                              f"{MIN_TARGETS} are needed")
    inner = targets.r < MIN_RADIUS_FACTOR * a
    if np.any(inner):
        raise RimTargetsError(f"{targets.source}: {int(inner.sum())} of {len(targets)} targets lie "
                              f"inside {MIN_RADIUS_FACTOR:g} x the rim radius {a:g} m (the closest "
                              f"to the centre at r = {float(targets.r.min()):.3g} m); rim targets "
                              "must lie near the rim")
    far = targets.r > MAX_RADIUS_FACTOR * a
    if np.any(far):
        raise RimTargetsError(f"{targets.source}: {int(far.sum())} targets lie beyond "
                              f"{MAX_RADIUS_FACTOR:g} x the rim radius {a:g} m (wrong units?)")
    if np.any(np.abs(targets.dz) > 0.01 * a):
        raise RimTargetsError(f"{targets.source}: dz values up to {np.max(np.abs(targets.dz)):g} m "
                              "look too large for a surface error (dz must be in metres)")


def harmonic_order(targets: RimTargets, max_harmonics: int = MAX_HARMONICS) -> int:
    """Fourier order K the targets support: by count, by the widest angular gap, and a cap."""
    phi = np.sort(targets.phi)
    gaps = np.diff(np.concatenate([phi, phi[:1] + 2.0 * np.pi]))
    by_gap = int(np.floor(np.pi / max(float(gaps.max()), 1e-12)))
    order = min(max_harmonics, (len(targets) - 1) // 2, by_gap)
    if order < 1:
        raise RimTargetsError(f"{targets.source}: the targets leave a gap of "
                              f"{np.degrees(gaps.max()):.0f} deg around the rim; spread them out")
    return order


def fit_harmonic(targets: RimTargets, misfit: NDArray[np.float64], a: float,
                 max_harmonics: int = MAX_HARMONICS) -> RimSeries:
    """Least-squares harmonic polynomial h with h(target) = misfit (m) at the targets."""
    order = harmonic_order(targets, max_harmonics)
    k = np.arange(order + 1)
    rho = (targets.r / a)[:, None] ** k
    phi = targets.phi[:, None]
    design = np.concatenate([rho * np.cos(k * phi), (rho * np.sin(k * phi))[:, 1:]], axis=1)
    coef, *_ = np.linalg.lstsq(design, misfit, rcond=None)
    sin = np.concatenate([[0.0], coef[order + 1:]])
    return RimSeries(float(a), coef[: order + 1], sin)
