"""Obstacles in the beam: a feed cabin or subreflector, support legs, any mesh; their triangles.

Frame and units of docs/physics.md: reflector vertex at the origin, axis +z, focus (0, 0, F),
metres, radians. An obstacle is a frozen spec (what a scene's ``[[obstacle]]`` table says,
checked by :mod:`raysim.scene.obstacles`); :func:`obstacle_mesh` turns the specs of a dish of
focal length F into one float64 triangle set, :class:`ObstacleMesh`, that the engines shadow
rays with (:mod:`raysim.optics.blockage`). The obstacles are opaque and absorbing: what they
block is gone (no reflection off them, no field of their own).

- :class:`Disk`: a flat disk of ``radius`` at height ``z`` on the axis, facing the dish (a feed
  cabin's or subreflector's silhouette). The polygon is circumscribed, so every point within
  ``radius`` of the axis lies under it.
- :class:`Legs`: ``count`` straight legs (a tripod, a quadripod) of square cross-section
  ``width`` x ``width``, each from its foot on the ideal paraboloid at ``foot_radius`` to its
  apex at height ``apex_z`` and distance ``apex_radius`` from the axis, the first at azimuth
  ``rotation`` and the others evenly spaced. One pair of the box's faces is horizontal-
  tangential (perpendicular to the plane through the axis and the leg), so the leg's
  silhouette along the axis is a strip ``width`` wide along its azimuth.
- :class:`MeshObstacle`: the triangles of any file trimesh reads, scaled by ``unit`` to metres,
  in the reflector frame as they stand in the file.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from raysim.errors import MeshError

DISK_SEGMENTS = 128  # sides of the disk's polygon: its inscribed circle is the disk


@dataclass(frozen=True)
class Disk:
    """A flat disk of ``radius`` (m) centred on the axis at height ``z`` (m above the vertex)."""

    radius: float
    z: float

    def describe(self) -> str:
        return f"disk r={self.radius:g} m at z={self.z:g} m"


@dataclass(frozen=True)
class Legs:
    """``count`` legs ``width`` (m) square from feet at ``foot_radius`` (m, on the ideal dish)
    to apexes at height ``apex_z`` (m; None: the focus) and ``apex_radius`` (m) off the axis,
    the first at azimuth ``rotation`` (rad)."""

    count: int
    width: float
    foot_radius: float
    apex_z: float | None = None
    apex_radius: float = 0.0
    rotation: float = 0.0

    def describe(self) -> str:
        apex = "the focus" if self.apex_z is None else f"z={self.apex_z:g} m"
        return (f"{self.count} legs {self.width:g} m wide, feet at r={self.foot_radius:g} m, apex at "
                f"{apex} r={self.apex_radius:g} m, first at {math.degrees(self.rotation):g} deg")


@dataclass(frozen=True)
class MeshObstacle:
    """The triangles of the mesh file ``path`` (any format trimesh reads) times ``unit`` (m)."""

    path: Path
    unit: float = 1.0

    def describe(self) -> str:
        return f"mesh {self.path.name} (x {self.unit:g} m)"


Obstacle = Disk | Legs | MeshObstacle


@dataclass(frozen=True, eq=False)
class ObstacleMesh:
    """Every obstacle of a scene as one triangle set: ``vertices`` (n, 3) float64 (m, reflector
    frame), ``faces`` (m, 3) int64; ``description`` says what they are in one line."""

    vertices: NDArray[np.float64]
    faces: NDArray[np.int64]
    description: str = ""

    def digest(self) -> str:
        """A digest of the triangles (equal digests: the same obstacles)."""
        h = hashlib.blake2b(np.ascontiguousarray(self.vertices, dtype=np.float64).tobytes(),
                            digest_size=16)
        h.update(np.ascontiguousarray(self.faces, dtype=np.int64).tobytes())
        return h.hexdigest()

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ObstacleMesh) and self.digest() == other.digest()

    def __hash__(self) -> int:
        return hash(self.digest())


def disk_triangles(disk: Disk) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The disk as a fan of DISK_SEGMENTS triangles about its centre (circumscribed polygon)."""
    n = DISK_SEGMENTS
    outer = disk.radius / math.cos(math.pi / n)  # the polygon's inscribed circle is the disk
    a = 2.0 * np.pi * np.arange(n) / n
    rim = np.column_stack([outer * np.cos(a), outer * np.sin(a), np.full(n, disk.z)])
    vertices = np.vstack([[0.0, 0.0, disk.z], rim])
    k = np.arange(n)
    faces = np.column_stack([np.zeros(n, dtype=np.int64), 1 + k, 1 + (k + 1) % n])
    return vertices, faces


# the 12 triangles of a box whose corners are numbered (end, s, t) -> 4 * end + 2 * s + t
_BOX_FACES = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5],   # the two ends
                       [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],   # the two t-faces
                       [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]],  # the two s-faces
                      dtype=np.int64)


def leg_ends(legs: Legs, F: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The feet and apexes (count, 3) of the legs' centre lines (m), on a dish of focal length F."""
    phi = legs.rotation + 2.0 * np.pi * np.arange(legs.count) / legs.count
    c, s = np.cos(phi), np.sin(phi)
    z_foot = legs.foot_radius**2 / (4.0 * F)
    apex_z = F if legs.apex_z is None else legs.apex_z
    feet = np.column_stack([legs.foot_radius * c, legs.foot_radius * s, np.full(legs.count, z_foot)])
    apexes = np.column_stack([legs.apex_radius * c, legs.apex_radius * s, np.full(legs.count, apex_z)])
    return feet, apexes


def leg_triangles(legs: Legs, F: float) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Each leg as a box ``width`` square about its centre line (8 vertices, 12 triangles)."""
    feet, apexes = leg_ends(legs, F)
    half = 0.5 * legs.width
    vertices, faces = [], []
    for k, (a, b) in enumerate(zip(feet, apexes, strict=True)):
        axis = (b - a) / np.linalg.norm(b - a)
        phi = math.atan2(a[1] + b[1], a[0] + b[0]) if np.hypot(*(a + b)[:2]) > 0 else legs.rotation
        s = np.array([-math.sin(phi), math.cos(phi), 0.0])  # horizontal, across the leg's plane
        t = np.cross(axis, s)  # in the leg's plane, across the leg
        corners = [end + side_s * half * s + side_t * half * t
                   for end in (a, b) for side_s in (-1, 1) for side_t in (-1, 1)]
        vertices.append(np.array(corners))
        faces.append(_BOX_FACES + 8 * k)
    return np.vstack(vertices), np.vstack(faces)


def mesh_triangles(obstacle: MeshObstacle) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The triangles of a mesh file, scaled to metres (MeshError if unreadable or empty)."""
    import trimesh

    path = obstacle.path
    if not path.is_file():
        raise MeshError(f"{path}: no such obstacle mesh file")
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many kinds for unreadable files
        raise MeshError(f"{path}: trimesh cannot read the obstacle mesh "
                        f"({exc.__class__.__name__}: {exc})") from exc
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError(f"{path}: the obstacle mesh holds no triangles")
    vertices = np.asarray(mesh.vertices, dtype=np.float64) * obstacle.unit
    if not np.all(np.isfinite(vertices)):
        raise MeshError(f"{path}: the obstacle mesh holds vertices that are not finite numbers")
    return vertices, np.asarray(mesh.faces, dtype=np.int64)


def obstacle_mesh(obstacles: tuple[Obstacle, ...] | list[Obstacle], F: float) -> ObstacleMesh | None:
    """One :class:`ObstacleMesh` of ``obstacles`` on a dish of focal length ``F`` (m); None when
    there are none."""
    if not obstacles:
        return None
    vertices, faces, offset = [], [], 0
    for obstacle in obstacles:
        if isinstance(obstacle, Disk):
            v, f = disk_triangles(obstacle)
        elif isinstance(obstacle, Legs):
            v, f = leg_triangles(obstacle, F)
        else:
            v, f = mesh_triangles(obstacle)
        vertices.append(v)
        faces.append(f + offset)
        offset += len(v)
    return ObstacleMesh(np.vstack(vertices), np.vstack(faces),
                        "; ".join(o.describe() for o in obstacles))
