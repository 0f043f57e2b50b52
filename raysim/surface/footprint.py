"""The footprint of a mesh seen along z: whether each vertex stands clear of the other faces.

A mesh whose vertices each lie, in the (x, y) plane, farther than ``clearance`` from every
face that does not have them as a corner is a graph over the plane around its vertices:
a line along z through a vertex meets that vertex's own faces only. Moving vertices along z
(a deformed twin) keeps every (x, y), so it keeps this property; a GO trace of a wave along
-z may then take every vertex ray as lit without asking a BVH (the faces it could meet all
meet it at its own point). Frame and units of docs/physics.md (metres).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

CLEARANCE = 1e-3  # m: far above float32 round-off of the BVH's coordinates (4 um at 55 m)


def vertices_clear_of_other_faces(vertices: NDArray, faces: NDArray, clearance: float = CLEARANCE,
                                  chunk: int = 1 << 17) -> bool:
    """Whether every vertex lies farther than ``clearance`` (m, in x, y) from every face it
    is not a corner of (see the module docstring); faces must be non-degenerate in (x, y)."""
    from scipy.spatial import cKDTree

    xy = np.asarray(vertices, dtype=np.float64)[:, :2]
    faces = np.asarray(faces, dtype=np.int64)
    tree = cKDTree(xy)
    for lo in range(0, len(faces), chunk):
        f = faces[lo:lo + chunk]
        corners = xy[f]  # (n, 3, 2)
        centre = corners.mean(axis=1)
        # a vertex within ``clearance`` of a face lies within this disk about its centroid
        reach = np.sqrt(((corners - centre[:, None, :]) ** 2).sum(axis=2)).max(axis=1) + clearance
        k = 8
        while True:  # the k nearest vertices of each centroid, k grown until none is cut off
            dist, near = tree.query(centre, k=min(k, len(xy)), distance_upper_bound=float(reach.max()))
            if k >= len(xy) or not np.any(dist[:, -1] <= reach):
                break
            k *= 2
        rows, cols = np.nonzero(dist <= reach[:, None])
        vertex = near[rows, cols]
        other = ~(f[rows] == vertex[:, None]).any(axis=1)
        if np.any(_distance(xy[vertex[other]], corners[rows[other]]) <= clearance):
            return False
    return True


def _distance(p: NDArray, tri: NDArray) -> NDArray[np.float64]:
    """Distance (m) from points p (n, 2) to the triangles tri (n, 3, 2) in the plane."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]

    def cross(u, v):
        return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]

    area = cross(b - a, c - a)
    sign = np.sign(area)
    inside = ((sign * cross(b - a, p - a) >= 0) & (sign * cross(c - b, p - b) >= 0)
              & (sign * cross(a - c, p - c) >= 0))
    out = np.full(len(p), np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        d = v - u
        t = np.clip(((p - u) * d).sum(axis=1) / np.maximum((d * d).sum(axis=1), 1e-300), 0.0, 1.0)
        out = np.minimum(out, np.hypot(*(u + t[:, None] * d - p).T))
    return np.where(inside, 0.0, out)
