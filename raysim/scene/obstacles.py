"""The ``[[obstacle]]`` tables of a scene -> frozen obstacle specs (:mod:`raysim.surface.obstacles`).

Units at this edge: metres (``*_m``) and degrees (``*_deg``); the specs are in metres and
radians, in the reflector frame (vertex at the origin, axis +z, focus at z = F). Types:

- ``disk``: ``radius_m``, ``z_m`` (height above the vertex; the focus height F when absent);
- ``legs``: ``count``, ``width_m``, ``foot_radius_m`` (where the feet stand on the dish),
  ``apex_z_m`` (default F), ``apex_radius_m`` (default 0: the legs meet on the axis),
  ``rotation_deg`` (azimuth of the first leg, default 0: along +x);
- ``mesh``: ``file`` (any mesh trimesh reads, relative to the scene file), ``unit_m`` (metres
  per file unit, default 1).

Every defect raises :class:`~raysim.errors.SceneError` naming the file and the key.
"""

from __future__ import annotations

from pathlib import Path

from raysim.surface.obstacles import Disk, Legs, MeshObstacle, Obstacle
from raysim.tomlschema import Table

OBSTACLE_KEYS: dict[str, tuple[str, ...]] = {
    "disk": ("radius_m", "z_m"),
    "legs": ("count", "width_m", "foot_radius_m", "apex_z_m", "apex_radius_m", "rotation_deg"),
    "mesh": ("file", "unit_m"),
}
OBSTACLE_TYPES = tuple(OBSTACLE_KEYS)
MAX_LEGS = 16
MAX_HEIGHT_M = 1000.0  # far above any dish's focus: a unit mistake


def obstacles_of(tables: list[Table], D: float | None, F: float | None,
                 base: Path) -> tuple[Obstacle, ...]:
    """The specs of the ``[[obstacle]]`` tables of a dish of diameter ``D`` and focal length
    ``F`` (m; None for a mesh dish fitted later, whose checks against D and F are then skipped);
    relative files resolve against ``base``."""
    out: list[Obstacle] = []
    for t in tables:
        kind = t.string("type", choices=OBSTACLE_TYPES)
        t.refuse_unknown({"type", *OBSTACLE_KEYS[kind]})
        out.append(_one(t, kind, D, F, base))
        t.done()
    return tuple(out)


def _one(t: Table, kind: str, D: float | None, F: float | None, base: Path) -> Obstacle:
    if kind == "mesh":
        path = t.file("file", base)
        return MeshObstacle(path, t.number("unit_m", 1.0, lo=0.0, lo_open=True, unit="m"))
    if kind == "disk":
        radius = t.number("radius_m", lo=0.0, lo_open=True, unit="m")
        if D is not None and radius >= D / 2:
            raise t.fail(f"'{t.name('radius_m')}' = {radius:g} m covers the whole dish "
                         f"(D/2 = {D / 2:g} m)")
        z = _height(t, "z_m", F)
        return Disk(radius, z)
    count = t.integer("count", lo=1, hi=MAX_LEGS)
    width = t.number("width_m", lo=0.0, lo_open=True, unit="m")
    foot = t.number("foot_radius_m", lo=0.0, lo_open=True, unit="m")
    if D is not None and foot > D / 2:
        raise t.fail(f"'{t.name('foot_radius_m')}' = {foot:g} m is beyond the rim (D/2 = {D / 2:g} m)")
    apex_r = t.number("apex_radius_m", 0.0, lo=0.0, unit="m")
    if apex_r >= foot:
        raise t.fail(f"'{t.name('apex_radius_m')}' = {apex_r:g} m must be smaller than "
                     f"'{t.name('foot_radius_m')}' = {foot:g} m")
    if width >= foot:
        raise t.fail(f"'{t.name('width_m')}' = {width:g} m is as wide as the feet's radius "
                     f"{foot:g} m: is it in mm?")
    apex_z = _height(t, "apex_z_m", F)
    if F is not None and apex_z <= foot**2 / (4.0 * F):
        raise t.fail(f"'{t.name('apex_z_m')}' = {apex_z:g} m is not above the feet (at z = "
                     f"{foot**2 / (4.0 * F):g} m on the dish)")
    rotation = t.angle("rotation_deg", 0.0)
    return Legs(count, width, foot, apex_z if t.has("apex_z_m") else None, apex_r, rotation)


def _height(t: Table, key: str, F: float | None) -> float:
    """A height above the vertex (m), default the focus height F."""
    if not t.has(key) and F is None:
        raise t.fail(f"missing key '{t.name(key)}' (the dish's focal length is not known yet)")
    z = t.number(key, F, lo=0.0, lo_open=True, unit="m")
    if z > MAX_HEIGHT_M:
        raise t.fail(f"'{t.name(key)}' = {z:g} m is far above any dish: is it in mm?")
    return z
