"""The shadow tests every engine shares: does the plane wave reach a point on the reflector, and
does an obstacle cross a ray's path (:func:`blocked_segments`)?

Warp's BVH holds the mesh in float32 (a 4 um step at 55 m), so it only decides which face a ray
meets first; the caller keeps its geometry in float64. A ray of the incident wave starts
``standoff`` metres up-beam of the point and travels along k_hat; the point is lit when the
first face the ray meets is the point's own face, or lies no more than ``tolerance`` metres
before the point (a neighbour sharing the edge, or the facet of a neighbouring panel that
overlaps it in projection by the facets' sag: see :func:`raysim.optics.bvh.shadow_tolerance`).
A ray that meets nothing is float32 round-off at the edge of a face: lit.
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.f64 import F64_TWO

wp.set_module_options({"enable_backward": False})



@wp.kernel
def lit_points(
    mesh: wp.uint64,
    points: wp.array(dtype=wp.vec3d),
    face: wp.array(dtype=wp.int32),
    k_hat: wp.vec3d,
    standoff: wp.float64,
    tolerance: wp.float64,
    lit: wp.array(dtype=wp.int32),
    offset: int,
):
    """lit[i] = 1 when the wave reaches points[i] (on face face[i]; -1: a vertex, any face)."""
    i = wp.tid() + offset
    p = points[i]
    origin = p - standoff * k_hat
    q = wp.mesh_query_ray(mesh, wp.vec3(origin), wp.normalize(wp.vec3(k_hat)), float(standoff * F64_TWO))
    lit[i] = 1
    if q.result:
        if q.face != face[i] and wp.float64(q.t) < standoff - tolerance:
            lit[i] = 0


@wp.kernel
def blocked_segments(
    mesh: wp.uint64,
    origins: wp.array(dtype=wp.vec3d),
    ends: wp.array(dtype=wp.vec3d),
    blocked: wp.array(dtype=wp.int32),
    offset: int,
):
    """blocked[i] = 1 when a face of ``mesh`` (an obstacle) crosses the segment origins[i] ->
    ends[i]; a segment of zero length is never blocked."""
    i = wp.tid() + offset
    d = ends[i] - origins[i]
    length = wp.length(d)
    blocked[i] = 0
    if length > wp.float64(0.0):
        q = wp.mesh_query_ray(mesh, wp.vec3(origins[i]), wp.vec3(d / length), float(length))
        if q.result:
            blocked[i] = 1
