"""The probe on the sphere: what the power meter reads, a polarisation and a pattern.

Frame and units (docs/physics.md): reflector frame, angles in radians. The probe sits on the
sphere of radius R about the focus with its axis on the radius: it faces the dish, and its
boresight is the direction from the probe to the focus, the direction in which the ideal
dish's reflected rays arrive. A wave arriving along the unit vector ``d`` (its direction of
travel) meets the probe at the angle ``alpha = acos(d . b)`` off boresight (``b`` the unit
vector from the probe to the focus).

A probe has

- a polarisation: the unit vector ``p = (cos psi, sin psi, 0)`` in the reflector frame's x-y
  plane (``psi`` rad from x), or none (an ideal |E|^2 power meter, the default);
- a power pattern ``g(alpha)``: ``max(cos alpha, 0)^q`` (q >= 0; q = 0 is isotropic), or a
  table of (alpha, relative power) interpolated linearly (held beyond its ends).

It reads ``P = g(alpha) |p_t . E|^2`` per arriving wave, ``p_t`` the polarisation projected onto
the plane transverse to ``d`` and normalised (the probe's co-polar direction for that wave); a
probe without polarisation reads ``g(alpha) |E|^2``. The ideal meter (no polarisation, q = 0)
reads |E|^2 and is what a FieldMap without probe attributes was measured with.

FieldMap attributes (flat, docs/data.md): ``probe`` (one line), ``probe_polarization`` (rad;
absent for none), ``probe_pattern`` (``cos^q`` or ``table``), ``probe_pattern_q``, and for a
table ``probe_pattern_angle`` (rad) and ``probe_pattern_power``. The ideal meter writes none.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.errors import FieldMapError, ProbeError, RaysimError
from raysim.maps.sphere import aperture_radius
from raysim.tomlschema import Table

PROBE_KEYS = ("polarization_deg", "pattern_q", "pattern")
MAX_Q = 1000.0  # cos^q beyond this is a pencil beam no probe has
TINY = 1e-12  # |p_t| below this: the polarisation lies along the arriving wave, no response


@dataclass(frozen=True)
class Probe:
    """A probe: ``polarization`` (rad from x in the x-y plane; None: none), a cos^q power
    pattern (``q`` >= 0) or a ``table`` of (alpha rad, relative power) rows, angles increasing
    in [0, pi]."""

    polarization: float | None = None
    q: float = 0.0
    table: tuple[tuple[float, float], ...] | None = None

    def __post_init__(self) -> None:
        check_probe(self.polarization, self.q, self.table, ProbeError)

    @property
    def ideal(self) -> bool:
        """Whether this is the ideal |E|^2 meter (no polarisation, isotropic cos^0 pattern)."""
        return self.polarization is None and self.table is None and self.q == 0.0

    @property
    def p_hat(self) -> NDArray[np.float64] | None:
        """The polarisation unit vector (reflector frame), or None."""
        if self.polarization is None:
            return None
        return np.array([math.cos(self.polarization), math.sin(self.polarization), 0.0])

    def pattern(self, alpha: ArrayLike) -> NDArray[np.float64]:
        """Relative power g(alpha) at angles ``alpha`` (rad) off boresight."""
        alpha = np.asarray(alpha, dtype=np.float64)
        if self.table is not None:
            angles, power = np.array(self.table).T
            return np.interp(alpha, angles, power)
        if self.q == 0.0:
            return np.ones_like(alpha)
        return np.maximum(np.cos(alpha), 0.0) ** self.q

    def co_polar(self, d: ArrayLike) -> NDArray[np.float64] | None:
        """p_t (..., 3): the polarisation projected transverse to arrival directions ``d``
        (unit, (..., 3)) and normalised; zero where p lies along d. None without polarisation."""
        p = self.p_hat
        if p is None:
            return None
        d = np.asarray(d, dtype=np.float64)
        t = p - (d @ p)[..., None] * d
        norm = np.linalg.norm(t, axis=-1, keepdims=True)
        return np.where(norm > TINY, t / np.maximum(norm, TINY), 0.0)

    def weight(self, d: ArrayLike, b: ArrayLike, e: ArrayLike) -> NDArray[np.float64]:
        """What the probe reads per unit intensity of real unit polarisations ``e`` (..., 3)
        arriving along ``d`` (unit, (..., 3)) at a probe of boresight ``b`` (unit, (..., 3)):
        g(alpha) (p_t . e)^2 (GO ray tubes)."""
        d = np.asarray(d, dtype=np.float64)
        g = self.pattern(_off_boresight(d, b))
        pt = self.co_polar(d)
        if pt is None:
            return g * np.sum(np.asarray(e, dtype=np.float64) ** 2, axis=-1)
        return g * np.sum(pt * e, axis=-1) ** 2

    def power(self, E: ArrayLike, d: ArrayLike, b: ArrayLike | None = None) -> NDArray[np.float64]:
        """What the probe reads of complex fields ``E`` (..., 3) arriving along ``d`` (unit,
        (..., 3)): g(alpha) |p_t . E|^2, alpha the angle between ``d`` and the boresight ``b``
        (None: along ``d``, alpha = 0). The ideal meter gives |E|^2 exactly."""
        E = np.asarray(E)
        if self.ideal:
            return np.sum(np.abs(E) ** 2, axis=-1)
        d = np.asarray(d, dtype=np.float64)
        g = self.pattern(np.zeros(d.shape[:-1]) if b is None else _off_boresight(d, b))
        pt = self.co_polar(d)
        if pt is None:
            return g * np.sum(np.abs(E) ** 2, axis=-1)
        return g * np.abs(np.sum(pt * E, axis=-1)) ** 2

    def vector(self, d: ArrayLike) -> NDArray[np.float64] | None:
        """sqrt(g(0)) p_t (..., 3) for waves arriving on boresight along ``d``: the real vector
        v with :meth:`power` = |v . E|^2 (what a linearisation needs); None without
        polarisation."""
        pt = self.co_polar(d)
        return None if pt is None else math.sqrt(float(self.pattern(0.0))) * pt

    def describe(self) -> str:
        """One line: the polarisation and the pattern."""
        if self.ideal:
            return "ideal |E|^2 power meter"
        pol = ("no polarisation (|E|^2)" if self.polarization is None else
               f"polarised at {math.degrees(self.polarization):g} deg from x")
        if self.table is not None:
            pattern = f"tabulated pattern ({len(self.table)} rows)"
        else:
            pattern = f"cos^{self.q:g} pattern"
        return f"{pol}, {pattern}"

    def attrs(self) -> dict[str, Any]:
        """The probe as flat FieldMap attributes (none for the ideal meter)."""
        if self.ideal:
            return {}
        out: dict[str, Any] = {"probe": self.describe(),
                               "probe_pattern": "table" if self.table is not None else "cos^q",
                               "probe_pattern_q": float(self.q)}
        if self.polarization is not None:
            out["probe_polarization"] = float(self.polarization)
        if self.table is not None:
            angles, power = np.array(self.table).T
            out["probe_pattern_angle"] = angles
            out["probe_pattern_power"] = power
        return out


def _off_boresight(d: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """alpha (rad): the angle between unit vectors d and b (..., 3)."""
    return np.arccos(np.clip(np.sum(np.asarray(d) * np.asarray(b), axis=-1), -1.0, 1.0))


def check_probe(polarization: float | None, q: float, table: Any, error: type[RaysimError],
                where: str = "probe") -> None:
    """Refuse what is not a probe (raising ``error`` naming ``where``): a polarisation angle
    that is not finite, q outside 0..MAX_Q, both q and a table, a table of fewer than two
    (angle rad, power) rows, not increasing in angle, angles outside 0..pi, powers negative,
    not finite or all zero."""
    if polarization is not None and not math.isfinite(polarization):
        raise error(f"{where}: the polarisation angle must be finite, got {polarization}")
    if isinstance(q, bool) or not isinstance(q, int | float) or not math.isfinite(q) \
            or not 0.0 <= q <= MAX_Q:
        raise error(f"{where}: the pattern's q must be a number in 0..{MAX_Q:g}, got {q!r}")
    if table is None:
        return
    if q != 0.0:
        raise error(f"{where}: give a cos^q pattern or a table, not both")
    rows = np.asarray(table, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] != 2 or len(rows) < 2:
        raise error(f"{where}: the pattern table needs at least two [angle_deg, power] rows")
    if not np.all(np.isfinite(rows)):
        raise error(f"{where}: the pattern table must hold finite numbers")
    angles, power = rows.T
    if angles.min() < 0.0 or angles.max() > math.pi + 1e-12:
        raise error(f"{where}: the pattern table's angles must lie in 0..180 deg, got "
                    f"{math.degrees(angles.min()):g}..{math.degrees(angles.max()):g}")
    if np.any(np.diff(angles) <= 0.0):
        raise error(f"{where}: the pattern table's angles must increase from row to row")
    if np.any(power < 0.0):
        raise error(f"{where}: the pattern table's relative powers must be >= 0")
    if not np.any(power > 0.0):
        raise error(f"{where}: the pattern table's relative powers are all 0: a pattern needs "
                    "some positive power (the probe would read nothing)")


IDEAL = Probe()  # the ideal |E|^2 power meter, the default


def probe_from_table(t: Table) -> Probe:
    """A probe from a ``[probe]`` table (scene or rig file), failing with the table's error:
    ``polarization_deg`` (a number, or ``"none"``, the default), ``pattern_q`` (cos^q) or
    ``pattern`` (rows [angle_deg, relative power])."""
    pol = None
    if t.raw("polarization_deg", "none") != "none":
        pol = t.angle("polarization_deg")
    q = t.number("pattern_q", 0.0)
    table = None
    if t.has("pattern"):
        rows = t.raw("pattern")
        name = t.name("pattern")
        if not isinstance(rows, list) or not all(
                isinstance(r, list) and len(r) == 2 and all(
                    isinstance(v, int | float) and not isinstance(v, bool) for v in r)
                for r in rows):
            raise t.fail(f"'{name}' must be a list of [angle_deg, relative_power] rows, "
                         f"got {rows!r}")
        if t.has("pattern_q"):
            raise t.fail(f"give '{t.name('pattern_q')}' (cos^q) or '{name}' (a table), not both")
        table = tuple((math.radians(float(a)), float(p)) for a, p in rows)
    t.done()
    check_probe(pol, q, table, t.error, f"{t.source}: '{t.where or 'probe'}'")
    return Probe(pol, q, table)


def probe_of(attrs: Mapping[str, Any] | Any, source: str = "FieldMap") -> Probe:
    """The probe a FieldMap records (its attributes, or the dataset); the ideal meter when it
    records none."""
    attrs = getattr(attrs, "attrs", attrs)
    if "probe_pattern" not in attrs and "probe_polarization" not in attrs:
        return IDEAL
    try:
        pol = attrs.get("probe_polarization")
        pol = None if pol is None else float(pol)
        table = None
        if str(attrs.get("probe_pattern", "cos^q")) == "table":
            angles = np.atleast_1d(np.asarray(attrs["probe_pattern_angle"], dtype=np.float64))
            power = np.atleast_1d(np.asarray(attrs["probe_pattern_power"], dtype=np.float64))
            table = tuple(zip(angles.tolist(), power.tolist(), strict=True))
        q = float(attrs.get("probe_pattern_q", 0.0)) if table is None else 0.0
        return Probe(pol, q, table)
    except (KeyError, TypeError, ValueError, RaysimError) as exc:
        raise FieldMapError(f"{source}: unusable probe attributes ({exc})") from exc


def arrival_directions(directions: ArrayLike) -> NDArray[np.float64]:
    """The ideal dish's arrival directions (..., 3) at sphere points seen from the focus along
    unit ``directions``: the rays travel from the probe towards the focus, d = -u (and the
    probe's boresight is the same vector)."""
    return -np.asarray(directions, dtype=np.float64)


def ideal_polarization(theta: ArrayLike, phi: ArrayLike, F: float,
                       e_inc: ArrayLike = (1.0, 0.0, 0.0)) -> NDArray[np.float64]:
    """Unit polarisation (..., 3) of the ideal paraboloid's GO field at sphere directions
    (theta, phi) (rad) for an on-axis plane wave polarised along ``e_inc`` (unit, in the x-y
    plane): E_r = 2 (n . e) n - e at the aperture point r = 2F tan(theta / 2), azimuth phi,
    n the surface's unit normal there (a perfect conductor)."""
    theta, phi = np.broadcast_arrays(np.asarray(theta, dtype=np.float64),
                                     np.asarray(phi, dtype=np.float64))
    r = aperture_radius(theta, F)
    n = np.stack([-r * np.cos(phi) / (2 * F), -r * np.sin(phi) / (2 * F), np.ones_like(r)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    e = np.asarray(e_inc, dtype=np.float64)
    return 2.0 * (n @ e)[..., None] * n - e


def ideal_weight(probe: Probe, theta: ArrayLike, phi: ArrayLike, F: float,
                 polarization: float = 0.0) -> NDArray[np.float64]:
    """What ``probe`` reads of the ideal paraboloid's GO field per unit intensity at sphere
    directions (theta, phi) (rad), on-axis wave polarised at ``polarization`` (rad from x):
    the rays arrive on boresight, so g(0) (p_t . E_r)^2. 1 for the ideal meter."""
    theta, phi = np.broadcast_arrays(np.asarray(theta, dtype=np.float64),
                                     np.asarray(phi, dtype=np.float64))
    if probe.ideal:
        return np.ones_like(theta)
    st = np.sin(theta)
    u = np.stack([st * np.cos(phi), st * np.sin(phi), -np.cos(theta)], axis=-1)
    d = arrival_directions(u)
    e = ideal_polarization(theta, phi, F, (math.cos(polarization), math.sin(polarization), 0.0))
    return probe.weight(d, d, e)
