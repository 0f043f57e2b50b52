"""The reflector's Warp BVH and the one shadow rule of every engine (GO rays, PO samples, edges).

With obstacles in the beam (``Reflector.obstacles``) the BVH holds theirs beside it
(:class:`raysim.optics.blockage.ObstacleBVH`): a point is lit when neither the dish nor an
obstacle stands on its incident ray.

Warp's BVH holds float32 points: it finds the face a ray meets first, and the engines recompute
hit points and normals in float64 from the float64 vertices. A deformed twin shares the ideal
mesh's triangulation, so its BVH is the ideal one refitted to the moved vertices
(:meth:`ReflectorBVH.refit`) rather than built again.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.optics import runtime
from raysim.optics.blockage import ObstacleBVH
from raysim.surface.mesh import Reflector


def facet_sag(reflector: Reflector) -> float:
    """Largest distance (m) along z between a face's flat facet and the smooth surface, at the
    face centroids (0 for a mesh without a smooth surface)."""
    if reflector.surface is None or len(reflector.faces) == 0:
        return 0.0
    v, f = reflector.vertices, reflector.faces
    c = (v[f[:, 0]] + v[f[:, 1]] + v[f[:, 2]]) / 3.0  # five times faster than v[f].mean(axis=1)
    panel = reflector.surface_panel(np.arange(len(f)))
    return float(np.abs(reflector.surface.height(c[:, 0], c[:, 1], panel) - c[:, 2]).max())


def shadow_tolerance(reflector: Reflector) -> float:
    """How far (m) before a point another face may meet its ray without shadowing it: 1 mm
    plus twice the facets' sag. At a panel's edge the neighbouring panel's facet, a chord of
    the surface like its own, can overlap it in projection by that much without hiding it."""
    return 1e-3 + 2.0 * facet_sag(reflector)


def standoff(vertices: NDArray[np.float64]) -> float:
    """Where (m up-beam of a point) a shadow ray starts: beyond the whole mesh."""
    return float(np.ptp(vertices, axis=0).max() + 10.0)


def reflector_standoff(reflector: Reflector) -> float:
    """:func:`standoff` of the reflector and its obstacles together."""
    if reflector.obstacles is None:
        return standoff(reflector.vertices)
    return standoff(np.vstack([reflector.vertices, reflector.obstacles.vertices]))


@dataclass
class ReflectorBVH:
    """A reflector's faces in a Warp BVH on ``device``, with the shadow test's two lengths.

    ``standoff`` (m): where a shadow ray starts, up-beam of its point (beyond the obstacles
    too); ``tolerance`` (m): see :func:`shadow_tolerance`; ``obstacles``: the BVH of the
    reflector's obstacles (None without).
    """

    mesh: Any
    device: str
    standoff: float
    tolerance: float
    _points: Any = field(repr=False, default=None)
    obstacles: ObstacleBVH | None = None

    @classmethod
    def build(cls, reflector: Reflector, device: str | None = "cpu") -> ReflectorBVH:
        dev = runtime.resolve_device(device)
        mesh, points = runtime.warp_mesh(reflector.vertices, reflector.faces, dev)
        obstacles = None if reflector.obstacles is None else ObstacleBVH.build(reflector.obstacles, dev)
        return cls(mesh, dev, reflector_standoff(reflector), shadow_tolerance(reflector), points,
                   obstacles)

    def refit(self, reflector: Reflector) -> None:
        """Move the BVH to ``reflector``'s vertices (same triangulation) and refit it."""
        wp = runtime.init()
        self._points.assign(wp.array(reflector.vertices.astype(np.float32), dtype=wp.vec3,
                                     device=self.device))
        self.mesh.refit()
        self.standoff = reflector_standoff(reflector)
        self.tolerance = shadow_tolerance(reflector)

    def lit(self, points: ArrayLike, k_hat: ArrayLike, face: ArrayLike | None = None,
            obstacles: bool = True) -> NDArray[np.bool_]:
        """(n,) bool: the plane wave travelling along ``k_hat`` reaches each point (m).

        ``face`` (n,) gives each point's own face (a point on a facet); None for points that
        belong to several faces (vertices), which then count as lit unless a face lies more
        than ``tolerance`` in front of them. ``obstacles`` False leaves the obstacles out
        (the dish's own shadow alone).
        """
        from raysim.optics.kernels import visibility

        wp = runtime.init()
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        n = len(pts)
        if n == 0:
            return np.zeros(0, dtype=bool)
        faces = np.full(n, -1, np.int32) if face is None else np.asarray(face, dtype=np.int32)
        dev = self.device
        out = wp.zeros(n, dtype=wp.int32, device=dev)
        runtime.launch(visibility.lit_points, n,
                       [self.mesh.id, wp.array(pts, dtype=wp.vec3d, device=dev),
                        wp.array(faces, dtype=wp.int32, device=dev),
                        wp.vec3d(*np.asarray(k_hat, dtype=np.float64)), self.standoff,
                        self.tolerance, out], dev)
        lit = out.numpy().astype(bool)
        if obstacles and self.obstacles is not None:
            lit[lit] = ~self.obstacles.incident_blocked(pts[lit], k_hat, self.standoff)
        return lit
