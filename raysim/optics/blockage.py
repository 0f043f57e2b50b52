"""Obstacles in the beam: which rays they block, and which probe-sphere cells they hide.

Frame and units of docs/physics.md (reflector frame, metres; sphere of radius R about the focus).
The obstacles of :mod:`raysim.surface.obstacles` are opaque and absorbing. A ray is blocked
when an obstacle crosses either leg of its path: the incident leg, from far up-beam down to its
point on the dish, or the reflected leg, from the dish to where it enters the probe sphere.
:class:`ObstacleBVH` holds the obstacles' triangles in a Warp BVH (float32: a shadow's edge
moves by micrometres, nothing the data resolve) and tests segments
(:func:`raysim.optics.kernels.visibility.blocked_segments`). Which engine shadows what:

- GO (:mod:`raysim.optics.go`) drops every ray tube with a ray blocked on either leg;
- go+edge (:mod:`raysim.optics.geowave`) the same for its geometric wave; its edge points
  follow the incident shadow;
- PO and PTD: the current is zero where the incident ray is blocked, and edge points in the
  incident shadow carry no fringe current (both through :meth:`ReflectorBVH.lit
  <raysim.optics.bvh.ReflectorBVH.lit>`). The field they radiate is not blocked on its way to
  the probe (that would need a ray per source and field point), and nothing models the
  obstacles' own scattered field.

The FieldMap of a scene with obstacles records the ``blocked`` cells (:func:`fieldmap_variables`),
from the GO tubes of the ideal dish: the blocked share of a cell is the power of the tubes the
obstacles removed that would have landed in it over the power the clear dish sends it, and a
cell counts as blocked when that share exceeds :data:`BLOCKED_SHARE`. The inversion treats
blocked cells as missing samples.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.optics import runtime
from raysim.surface.obstacles import ObstacleMesh

BLOCKED_SHARE = 1e-6  # a cell is blocked when obstacles take more than this of its GO power
BLOCKAGE_RAY_SPACING = 0.15  # m: ray spacing of the GO trace that maps the blocked cells


@dataclass
class ObstacleBVH:
    """The obstacles' triangles in a Warp BVH on ``device``."""

    mesh: Any
    device: str
    _points: Any = field(repr=False, default=None)

    @classmethod
    def build(cls, obstacles: ObstacleMesh, device: str | None = "cpu") -> ObstacleBVH:
        dev = runtime.resolve_device(device)
        mesh, points = runtime.warp_mesh(obstacles.vertices, obstacles.faces, dev)
        return cls(mesh, dev, points)

    def blocked(self, origins: ArrayLike, ends: ArrayLike) -> NDArray[np.bool_]:
        """(n,) bool: an obstacle crosses the segment from each origin to its end (m)."""
        from raysim.optics.kernels import visibility

        wp = runtime.init()
        a = np.ascontiguousarray(np.asarray(origins, dtype=np.float64).reshape(-1, 3))
        b = np.ascontiguousarray(np.asarray(ends, dtype=np.float64).reshape(-1, 3))
        n = len(a)
        if n == 0:
            return np.zeros(0, dtype=bool)
        out = wp.zeros(n, dtype=wp.int32, device=self.device)
        runtime.launch(visibility.blocked_segments, n,
                       [self.mesh.id, wp.array(a, dtype=wp.vec3d, device=self.device),
                        wp.array(b, dtype=wp.vec3d, device=self.device), out], self.device)
        return out.numpy().astype(bool)

    def incident_blocked(self, points: ArrayLike, k_hat: ArrayLike, standoff: float) -> NDArray[np.bool_]:
        """(n,) bool: an obstacle stands on the incident ray to each point (m), the ray coming
        along ``k_hat`` from ``standoff`` metres up-beam (beyond every obstacle)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        k = np.asarray(k_hat, dtype=np.float64)
        return self.blocked(pts - standoff * k, pts)


def sphere_points(chart: NDArray[np.float64], focus: ArrayLike, radius: float) -> NDArray[np.float64]:
    """Points (n, 3) on the sphere of ``radius`` (m) about ``focus`` from their Lambert chart
    coordinates (n, 2) about -z (the inverse of :func:`raysim.optics.kernels.go.lambert`:
    |X|^2 = 2 (1 + u_z))."""
    X = np.asarray(chart, dtype=np.float64)
    uz = 0.5 * np.sum(X * X, axis=1) - 1.0
    scale = np.sqrt(np.maximum(0.5 * (1.0 - uz), 0.0))
    u = np.column_stack([X * scale[:, None], uz])
    return np.asarray(focus, dtype=np.float64) + radius * u


def blocked_share(kept: NDArray[np.float64], removed: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per cell, the share of the clear dish's power the obstacles removed: removed / (kept +
    removed) of the tube powers (0 where neither reaches the cell)."""
    total = kept + removed
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(total > 0, removed / total, 0.0)


def fieldmap_variables(share: NDArray[np.float64], obstacles: ObstacleMesh,
                       threshold: float = BLOCKED_SHARE) -> tuple[dict, dict]:
    """The FieldMap variables and attributes of the obstacles: ``blocked`` (theta, phi; uint8,
    1 where ``share`` exceeds ``threshold``), ``blocked_share``, and the obstacles' triangles
    ``obstacle_vertices`` (m, reflector frame) and ``obstacle_faces`` (so a reader, the
    inversion's forward model, has them without the scene)."""
    blocked = share > threshold
    extra = {
        "blocked": (("theta", "phi"), blocked.astype(np.uint8), {
            "units": "1", "long_name": "sphere cell hidden by obstacles (1) or not (0)",
            "rule": f"1 where obstacles remove more than {threshold:g} of the cell's GO power "
                    "from the ideal dish (a ray blocked on its incident or reflected leg)"}),
        "blocked_share": (("theta", "phi"), share, {
            "units": "1", "long_name": "share of the ideal dish's GO power in the cell that "
                                       "obstacles remove"}),
        "obstacle_vertices": (("obstacle_vertex", "xyz"), obstacles.vertices, {
            "units": "m", "long_name": "obstacle triangle vertices, reflector frame"}),
        "obstacle_faces": (("obstacle_face", "corner"), obstacles.faces.astype(np.int32), {
            "units": "1", "long_name": "obstacle triangles: indices into obstacle_vertices"}),
    }
    attrs = {"obstacles": obstacles.description, "blocked_threshold": float(threshold),
             "blocked_cells": int(blocked.sum())}
    return extra, attrs
