"""The scanning rig's kinematics and calibration, read from ``rig.toml``.

Frame (docs/physics.md): reflector vertex at the origin, axis +z, focus at (0, 0, F); every vector
here is taken from the focus, in metres. A semicircular track of radius R is centred at the
track centre C = focus + ``centre_offset``; the slider moves the probe along the track by the
geometric angle s (rad, s = 0 at the bottom of the track, facing the vertex), and the track
rotates about the feed axis (through C, parallel to z) by the angle a (rad). The probe then sits
at C + R u(s, a), u = (sin s cos a, sin s sin a, -cos s). Because the track is a full semicircle,
s runs over [-90, 90] deg and a needs only half a turn to cover the hemisphere.

The motion controller's axes read s + ``slider_zero`` and a + ``rotation_zero`` (rad here,
degrees at the instrument). Commanded sphere angles (theta, phi) go to axis positions that put
the probe on the ray from the focus in that direction (exact for a known centre offset, with the
probe then at distance ``t`` from the focus instead of R); axis positions come back to the
probe's true (theta, phi, r).

The probe itself (the rig file's optional ``[probe]`` table, :mod:`raysim.maps.probe`): its
polarisation in the reflector frame's x-y plane and its power pattern about its boresight, the
direction from the probe to the focus. Without the table the rig reads |E|^2 (an ideal meter).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from hardware.config import Table, plan_table, read_toml
from hardware.errors import PlanError
from raysim.maps.measurement import probe_point
from raysim.maps.probe import IDEAL, PROBE_KEYS, Probe, probe_from_table

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class Calibration:
    """Where the track really is: centre offset from the focus (m, x y z), axis zeros (rad)."""

    centre_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    slider_zero: float = 0.0
    rotation_zero: float = 0.0


@dataclass(frozen=True)
class Limits:
    """Travel limits of the slider and rotation axes, in axis readings (rad)."""

    slider_min: float = math.radians(-95.0)
    slider_max: float = math.radians(95.0)
    rotation_min: float = math.radians(-5.0)
    rotation_max: float = math.radians(185.0)


@dataclass(frozen=True)
class Rig:
    """The rig: track radius R (m), calibration, limits, park position and motion settings.

    ``park`` holds the (slider, rotation) axis readings (rad) of the position that clears the
    optical path; ``speed`` is the axes' velocity (rad/s), ``tolerance`` the largest accepted
    difference between a target and its read-back (rad), ``move_timeout_s`` the longest one
    move may take (s). ``resources`` are default VISA addresses by role (``meter``,
    ``motion``); ``visa_timeout_s`` bounds every instrument read (s). ``probe_response`` is what the
    power meter reads (polarisation and pattern; the ideal |E|^2 meter by default).
    """

    radius: float
    calibration: Calibration = Calibration()
    limits: Limits = Limits()
    park: tuple[float, float] = (math.radians(95.0), 0.0)
    slider_axis: int = 1
    rotation_axis: int = 2
    speed: float = math.radians(5.0)
    tolerance: float = math.radians(0.005)
    move_timeout_s: float = 120.0
    resources: dict[str, str] = field(default_factory=dict)
    visa_timeout_s: float = 2.0
    probe_response: Probe = IDEAL

    def with_calibration(self, calibration: Calibration) -> Rig:
        """The same rig with another calibration (e.g. a simulator's true one)."""
        return replace(self, calibration=calibration)

    def axes(self, theta: float, phi: float) -> tuple[float, float]:
        """Axis readings (slider, rotation) in rad that point the probe along (theta, phi).

        theta, phi (rad) are seen from the focus. Raises :class:`PlanError` when no axis
        position inside the limits reaches that direction.
        """
        d = direction(theta, phi)
        c = np.asarray(self.calibration.centre_offset, dtype=np.float64)
        t = ray_distance(d, c, self.radius)
        u = (t * d - c) / self.radius
        s = math.acos(float(np.clip(-u[2], -1.0, 1.0)))
        horizontal = math.hypot(float(u[0]), float(u[1]))
        a = math.atan2(float(u[1]), float(u[0])) if horizontal > 1e-12 else phi
        lim = self.limits
        for slider, rotation in ((s, a), (-s, a + math.pi)):
            axis_s = slider + self.calibration.slider_zero
            axis_r = _wrap_into(rotation + self.calibration.rotation_zero,
                                lim.rotation_min, lim.rotation_max)
            if axis_r is not None and lim.slider_min <= axis_s <= lim.slider_max:
                return axis_s, axis_r
        raise PlanError(f"theta {math.degrees(theta):.3f} deg, phi {math.degrees(phi):.3f} deg "
                        "is out of the rig's reach (see [limits] in the rig file)")

    def probe(self, slider: float, rotation: float) -> tuple[float, float, float]:
        """Probe position (theta, phi, r) seen from the focus, for axis readings in rad.

        theta, phi in rad (phi in [0, 2 pi)), r in m.
        """
        s = slider - self.calibration.slider_zero
        a = rotation - self.calibration.rotation_zero
        theta, phi, r = probe_point(s, a, self.radius, self.calibration.centre_offset)
        return float(theta), float(phi), float(r)

    def within_limits(self, slider: float, rotation: float) -> bool:
        """Whether axis readings (rad) lie inside the travel limits."""
        lim = self.limits
        return (lim.slider_min <= slider <= lim.slider_max
                and lim.rotation_min <= rotation <= lim.rotation_max)


def direction(theta: float, phi: float) -> np.ndarray:
    """Unit vector from the focus along (theta, phi) (rad): (sin t cos p, sin t sin p, -cos t)."""
    st = math.sin(theta)
    return np.array([st * math.cos(phi), st * math.sin(phi), -math.cos(theta)])


def ray_distance(d: np.ndarray, c: np.ndarray, R: float) -> float:
    """Distance t (m) from the focus along unit vector d to the circle |t d - c| = R (t > 0)."""
    dc = float(d @ c)
    disc = dc * dc - float(c @ c) + R * R
    if disc < 0 or float(c @ c) >= R * R:
        raise PlanError("the track centre offset is larger than the track radius")
    return dc + math.sqrt(disc)


def _wrap_into(angle: float, low: float, high: float) -> float | None:
    """angle + 2 pi k inside [low, high] for the smallest such value, or None."""
    k = math.ceil((low - angle) / TWO_PI - 1e-12)
    value = angle + k * TWO_PI
    return value if value <= high + 1e-12 else None


def load_rig(path: str | Path) -> tuple[Rig, str]:
    """Read a ``rig.toml``; return the rig and the file's text. Degrees in, radians out."""
    data, text, path = read_toml(path, "rig")
    return rig_from_table(plan_table(data, str(path))), text


def rig_from_table(top: Table) -> Rig:
    """Build a :class:`Rig` from a parsed rig table (see ``scenes/rig.toml`` for the keys)."""
    top.string("description", "")  # for the reader (and raysim scenes)
    track = top.sub("track", required=True)
    radius = track.number("radius_m", lo=0.0, lo_open=True)
    calibration = Calibration(
        centre_offset=track.vector3("centre_offset_m", (0.0, 0.0, 0.0)),
        slider_zero=track.angle("slider_zero_deg", 0.0, lo=-180.0, hi=180.0),
        rotation_zero=track.angle("rotation_zero_deg", 0.0, lo=-360.0, hi=360.0),
    )
    track.done()
    if math.dist(calibration.centre_offset, (0, 0, 0)) >= 0.5 * radius:
        raise track.fail("'track.centre_offset_m' must be well inside the track radius")
    lim_t = top.sub("limits", required=False)
    limits = Limits(
        slider_min=lim_t.angle("slider_min_deg", -95.0, lo=-180.0, hi=180.0),
        slider_max=lim_t.angle("slider_max_deg", 95.0, lo=-180.0, hi=180.0),
        rotation_min=lim_t.angle("rotation_min_deg", -5.0, lo=-720.0, hi=720.0),
        rotation_max=lim_t.angle("rotation_max_deg", 185.0, lo=-720.0, hi=720.0),
    )
    lim_t.done()
    if limits.slider_min >= limits.slider_max or limits.rotation_min >= limits.rotation_max:
        raise lim_t.fail("'limits': each minimum must be below its maximum")
    park_t = top.sub("park", required=False)
    park = (park_t.angle("slider_deg", 95.0), park_t.angle("rotation_deg", 0.0))
    park_t.done()
    motion = top.sub("motion", required=False)
    slider_axis = motion.integer("slider_axis", 1, lo=1)
    rotation_axis = motion.integer("rotation_axis", 2, lo=1)
    speed = motion.angle("speed_deg_s", 5.0, lo=0.0, lo_open=True)
    tolerance = motion.angle("tolerance_deg", 0.005, lo=0.0, lo_open=True)
    move_timeout_s = motion.number("timeout_s", 120.0, lo=0.0, lo_open=True)
    motion.done()
    if slider_axis == rotation_axis or max(slider_axis, rotation_axis) > 3:
        raise motion.fail("'motion': the two axes must be distinct ESP301 axes 1..3")
    inst = top.sub("instruments", required=False)
    resources = {role: value for role in ("meter", "motion")
                 if (value := inst.string(role, None)) is not None}
    visa_timeout_s = inst.number("timeout_s", 2.0, lo=0.0, lo_open=True)
    inst.done()
    probe = probe_from_table(top.sub("probe", keys=PROBE_KEYS))
    top.done()
    rig = Rig(radius=radius, calibration=calibration, limits=limits, park=park,
              slider_axis=slider_axis, rotation_axis=rotation_axis, speed=speed,
              tolerance=tolerance, move_timeout_s=move_timeout_s, resources=resources,
              visa_timeout_s=visa_timeout_s, probe_response=probe)
    if not rig.within_limits(*park):
        raise park_t.fail("'park': the park position lies outside the axis limits")
    return rig


def rig_attrs(rig: Rig) -> dict[str, Any]:
    """The rig's settings as flat FieldMap attributes (SI: m, rad), its probe's included
    (:meth:`raysim.maps.probe.Probe.attrs`: none for the ideal meter)."""
    cal = rig.calibration
    return {
        "rig_radius": rig.radius,
        "rig_centre_offset_x": cal.centre_offset[0],
        "rig_centre_offset_y": cal.centre_offset[1],
        "rig_centre_offset_z": cal.centre_offset[2],
        "rig_slider_zero": cal.slider_zero,
        "rig_rotation_zero": cal.rotation_zero,
        "rig_tolerance": rig.tolerance,
        **rig.probe_response.attrs(),
    }
