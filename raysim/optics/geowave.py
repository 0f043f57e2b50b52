"""The geometric (GO) reflected wave on the probe sphere as a complex field, from ray tubes.

Frame and units of docs/physics.md (metres, radians; sphere of radius R about the focus); time
convention exp(+j w t), incident wave E_inc = e_hat exp(-j k k_hat . r). Used by the go+edge
engine (:mod:`raysim.optics.goedge`); the GO engine (:mod:`raysim.optics.go`) deposits the same
tubes' power instead.

Rays start on a lattice of every mesh face (m-fold, shared along mesh edges so that every ray
sees all its tubes). Where a face has a free edge that is an arc (the rim, ring edges beside
gaps), the lattice is bent onto the arc, so the tubes end on the same curve as the edge
quadrature of :mod:`raysim.surface.edges`: the geometric wave's boundary on the sphere is then
the image of the very edge whose diffraction completes it. Each lit ray is lifted onto the
smooth surface (float64), reflected and followed to the sphere (:func:`reflect_rays` in
:mod:`raysim.optics.kernels.geowave`). Per ray:

- amplitude |E| = sqrt(sum P_t / sum A_t) over the tubes t around it: P_t the tube's
  incident cross-section, A_t its cross-section normal to the ray where it meets the sphere
  (the divergence of the tube; |E_r| = |E_i| on a perfect conductor);
- polarisation E_r = -e_hat + 2 (n . e_hat) n at the hit, carried unchanged along the ray;
- path L = k_hat . r_hit + |Q - r_hit|, the optical path from the incident wavefront through
  the float64 reflection point to the sphere point Q;
- the near-field factors of the free-space Green's function at the reflection point (see
  :mod:`raysim.optics.kernels.geowave`): the field is PO's stationary-phase value, which the
  edge currents of :mod:`raysim.optics.goedge` complete.

Obstacles (``Reflector.obstacles``, :mod:`raysim.optics.blockage`): a ray blocked on its way
in (the shadow test) or out (from its hit to the sphere) carries nothing, and neither do the
tubes it bounds.

Per tube: the number of caustics the tube crosses before the sphere (roots of its
cross-section, a quadratic in the distance along the rays), each a factor j. The field at a
point is the sum over the tubes that contain it (:func:`geometric_field`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from raysim.optics import runtime
from raysim.optics.bvh import ReflectorBVH
from raysim.optics.go import RayLattice, _lattice_tables, lift_to_surface
from raysim.optics.illumination import Illumination
from raysim.surface.mesh import Reflector
from raysim.surface.quadrature import free_edges

ARC_RTOL = 1e-9  # a free edge is an arc when its ends' radii agree to this (as the edge quadrature)


# --- the lattice --------------------------------------------------------------------------
def shared_lattice(reflector: Reflector, m: int, curve: bool = True) -> RayLattice:
    """Rays on the m-fold lattice of every face, one ray per lattice point shared by faces.

    Points on a mesh edge are computed once from the edge's two vertices; with ``curve`` and a
    smooth surface, faces with a free arc edge are bent onto the arc (points on the arc exactly,
    interior points shifted by the chord-to-arc offset times their weight towards it) and
    those points are put on the surface.
    """
    faces = reflector.faces
    v = reflector.vertices
    n_faces = len(faces)
    ij, local = _lattice_tables(m)
    W = np.rint(ij * m).astype(np.int64)  # integer weights on the face's vertices, sum m
    kind = (W > 0).sum(axis=1)  # 1 vertex, 2 edge, 3 interior
    pairs = np.array([(0, 1), (1, 2), (0, 2)])
    keys = np.sort(faces[:, pairs], axis=2)  # (F, 3, 2): each local edge's two vertex ids
    edge_keys, edge_of = np.unique(keys.reshape(-1, 2), axis=0, return_inverse=True)
    edge_of = edge_of.reshape(n_faces, 3)
    n_vertices, n_edges = len(v), len(edge_keys)
    n_interior = int((kind == 3).sum())
    gid = np.empty((n_faces, len(W)), dtype=np.int64)
    param = np.zeros((n_faces, len(W)), dtype=np.int64)  # weight of the higher vertex on an edge
    for p in range(len(W)):
        if kind[p] == 1:
            gid[:, p] = faces[:, int(np.argmax(W[p]))]
        elif kind[p] == 2:
            la, lb = np.flatnonzero(W[p] > 0)
            e = int(np.flatnonzero((pairs == (la, lb)).all(axis=1))[0])
            hi_is_b = faces[:, lb] > faces[:, la]
            k = np.where(hi_is_b, W[p, lb], W[p, la])
            param[:, p] = k
            gid[:, p] = n_vertices + edge_of[:, e] * (m - 1) + (k - 1)
    interior = np.flatnonzero(kind == 3)
    base = n_vertices + n_edges * max(m - 1, 0)
    gid[:, interior] = base + np.arange(n_faces)[:, None] * n_interior + np.arange(n_interior)[None, :]
    points = np.einsum("lk,fkc->flc", W / m, v[faces])
    normals = np.einsum("lk,fkc->flc", W / m, reflector.vertex_normals[faces])
    for p in np.flatnonzero(kind == 2):  # one formula per edge point, whatever face computes it
        la, lb = np.flatnonzero(W[p] > 0)
        lo = np.minimum(faces[:, la], faces[:, lb])
        hi = np.maximum(faces[:, la], faces[:, lb])
        t = (param[:, p] / m)[:, None]
        points[:, p] = (1.0 - t) * v[lo] + t * v[hi]
        normals[:, p] = (1.0 - t) * reflector.vertex_normals[lo] + t * reflector.vertex_normals[hi]
    panel = np.repeat(reflector.face_surface_panel[:, None], len(W), axis=1)
    if curve and reflector.arc_edges:
        _bend_onto_arcs(reflector, m, W, points)
    _, first, compact = np.unique(gid.ravel(), return_index=True, return_inverse=True)
    normals = normals.reshape(-1, 3)[first]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    tubes = compact.reshape(n_faces, len(W))[:, local].reshape(-1, 3)
    return RayLattice(points.reshape(-1, 3)[first], panel.ravel()[first], normals,
                      tubes.astype(np.int32))


def _bend_onto_arcs(reflector: Reflector, m: int, W: NDArray, points: NDArray) -> None:
    """Move the lattice points of faces with a free arc edge onto the arc (in place)."""
    v = reflector.vertices
    b, c, _, face = free_edges(reflector.faces)
    r = np.hypot(v[:, 0], v[:, 1])
    arc = (r[b] > 0) & (np.abs(r[b] - r[c]) <= ARC_RTOL * np.maximum(r[b], r[c]))
    b, c, face = b[arc], c[arc], face[arc]
    if len(face) == 0:
        return
    f = reflector.faces[face]
    lb = np.argmax(f == b[:, None], axis=1)
    lc = np.argmax(f == c[:, None], axis=1)
    wb = W[:, lb].T / m  # (E, L) weights of b and c at each lattice point of the face
    wc = W[:, lc].T / m
    near = wb + wc
    t = np.where(near > 0, wc / np.where(near > 0, near, 1.0), 0.0)
    rho = 0.5 * (r[b] + r[c])[:, None]
    phi_b = np.arctan2(v[b, 1], v[b, 0])[:, None]
    dphi = np.angle(np.exp(1j * (np.arctan2(v[c, 1], v[c, 0]) - phi_b[:, 0])))[:, None]
    phi = phi_b + t * dphi
    chord = v[b][:, None, :2] + t[..., None] * (v[c] - v[b])[:, None, :2]
    shift = np.stack([rho * np.cos(phi), rho * np.sin(phi)], axis=-1) - chord
    xy = points[face, :, :2] + near[..., None] * shift
    on_arc = np.isclose(near, 1.0, rtol=0.0, atol=1e-12)
    exact = np.stack([rho * np.cos(phi), rho * np.sin(phi)], axis=-1)
    xy = np.where(on_arc[..., None], exact, xy)
    # points with a weight on both ends of the arc: the arc's own and the face's interior ones
    # (the others are shared with neighbouring faces and stay where they are)
    moved = (wb > 0) & (wc > 0)
    panel = reflector.surface_panel(face)
    z = reflector.surface.height(xy[..., 0], xy[..., 1],
                                 None if panel is None else np.repeat(panel[:, None], xy.shape[1], 1))
    new = np.concatenate([xy, z[..., None]], axis=-1)
    points[face] = np.where(moved[..., None], new, points[face])


# --- tubes ---------------------------------------------------------------------------------
@dataclass
class Buckets:
    """Tubes listed by the chart cells (size 1 / inv_size) their bounding boxes meet."""

    origin: NDArray[np.float64]
    inv_size: float
    nx: int
    ny: int
    start: NDArray[np.int32]
    tubes: NDArray[np.int32]


def bucket_tubes(chart: NDArray, tubes: NDArray, valid: NDArray, max_cells: int = 4096) -> Buckets:
    """A uniform grid over the valid tubes' chart bounding boxes, each cell listing in
    ascending order the tubes whose box meets it (about two tubes per cell)."""
    ids = np.flatnonzero(valid)
    if len(ids) == 0:
        return Buckets(np.zeros(2), 1.0, 1, 1, np.zeros(2, dtype=np.int32), np.zeros(0, dtype=np.int32))
    t = tubes[ids]
    c0, c1, c2 = chart[t[:, 0]], chart[t[:, 1]], chart[t[:, 2]]
    lo = np.minimum(np.minimum(c0, c1), c2)
    hi = np.maximum(np.maximum(c0, c1), c2)
    origin = lo.min(axis=0)
    span = hi.max(axis=0) - origin
    extent = np.maximum(hi[:, 0] - lo[:, 0], hi[:, 1] - lo[:, 1])
    typical = float(np.partition(extent, len(extent) // 2)[len(extent) // 2])
    size = max(2.0 * typical, float(span.max()) / max_cells, 1e-12)
    nx, ny = (np.floor(span / size).astype(np.int64) + 1).tolist()
    i0 = np.floor((lo - origin) / size).astype(np.int64)
    i1 = np.minimum(np.floor((hi - origin) / size).astype(np.int64), [nx - 1, ny - 1])
    wx, wy = i1[:, 0] - i0[:, 0] + 1, i1[:, 1] - i0[:, 1] + 1
    count = wx * wy
    owner = np.repeat(np.arange(len(ids)), count)
    k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    cell = (i0[owner, 1] + k // wx[owner]) * nx + i0[owner, 0] + k % wx[owner]
    order = np.argsort(cell, kind="stable")  # tube ids stay ascending within a cell
    start = np.searchsorted(cell[order], np.arange(nx * ny + 1)).astype(np.int32)
    return Buckets(origin, 1.0 / size, int(nx), int(ny), start, ids[owner[order]].astype(np.int32))


def lambert_chart(directions: NDArray) -> NDArray[np.float64]:
    """The Lambert equal-area chart about -z of unit vectors (n, 3): (n, 2)."""
    u = np.asarray(directions, dtype=np.float64)
    scale = np.sqrt(2.0 / np.maximum(1.0 - u[:, 2], 1e-300))
    return scale[:, None] * u[:, :2]


# --- the trace -----------------------------------------------------------------------------
@dataclass
class GeometricWave:
    """The traced rays and tubes of one reflector on one sphere, ready for :meth:`field`."""

    device: str
    focus: NDArray[np.float64]
    radius: float
    k: float
    arrays: dict[str, Any]  # Warp arrays of the kernel, by argument name
    buckets: Buckets
    n_rays: int
    n_tubes: int
    n_lit: int
    n_missed: int
    n_valid_tubes: int
    n_caustic_tubes: int

    def field(self, points: NDArray) -> NDArray[np.complex128]:
        """E (n, 3) of the geometric wave at ``points`` (n, 3) on the sphere (m); each point alone."""
        from raysim.optics.kernels import geowave as K
        from raysim.optics.kernels.radiation import cis_table

        wp = runtime.init()
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        n = len(pts)
        if n == 0:
            return np.zeros((0, 3), dtype=np.complex128)
        u = pts - self.focus
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        dev, a, b = self.device, self.arrays, self.buckets
        E = wp.zeros((6, n), dtype=wp.float64, device=dev)
        runtime.launch(K.geometric_field, n, [
            wp.array(lambert_chart(u), dtype=wp.vec2d, device=dev), a["chart"], a["path"], a["distance"],
            a["amplitude"],
            a["longitudinal"], a["tubes"], a["turns"],
            wp.array(b.start, dtype=wp.int32, device=dev), wp.array(b.tubes, dtype=wp.int32, device=dev),
            wp.vec2d(*b.origin), float(b.inv_size), b.nx, b.ny, float(self.k),
            wp.array(cis_table(), dtype=wp.vec2d, device=dev), E], dev, min_chunk=256)
        e = E.numpy()
        return (e[:3] + 1j * e[3:]).T


def trace_wave(reflector: Reflector, focus, radius: float, wave: Illumination, subdivisions: int,
               device: str | None = "cpu", bvh: ReflectorBVH | None = None) -> GeometricWave:
    """Trace the lattice of ``reflector`` (m-fold, m = ``subdivisions``) to the sphere of
    ``radius`` (m) about ``focus`` and prepare its geometric wave (module docstring)."""
    from raysim.optics.kernels import geowave as K

    wp = runtime.init()
    dev = runtime.resolve_device(device)
    focus = np.asarray(focus, dtype=np.float64)
    k_hat, e_hat = wave.k_hat, wave.e_hat
    lattice = shared_lattice(reflector, subdivisions)
    n_rays = len(lattice.points)
    bvh = bvh if bvh is not None else ReflectorBVH.build(reflector, dev)
    lit = bvh.lit(lattice.points, k_hat)
    hits, normals = lift_to_surface(reflector, lattice, k_hat)
    ok = wp.array(lit.astype(np.int32), dtype=wp.int32, device=dev)
    out = {name: wp.zeros(n_rays, dtype=dtype, device=dev) for name, dtype in (
        ("chart", wp.vec2d), ("exit_point", wp.vec3d), ("direction", wp.vec3d), ("path", wp.float64),
        ("distance", wp.float64), ("polar", wp.vec3d))}
    runtime.launch(K.reflect_rays, n_rays, [
        wp.array(hits, dtype=wp.vec3d, device=dev), wp.array(normals, dtype=wp.vec3d, device=dev),
        wp.vec3d(*k_hat), wp.vec3d(*e_hat), wp.vec3d(*focus), float(radius), ok,
        out["chart"], out["exit_point"], out["direction"], out["path"], out["distance"], out["polar"]], dev)
    ok_np = ok.numpy().astype(bool)
    if bvh.obstacles is not None:  # the reflected leg: an obstacle between the hit and the sphere
        out_blocked = bvh.obstacles.blocked(hits[ok_np], out["exit_point"].numpy()[ok_np])
        ok_np[np.flatnonzero(ok_np)[out_blocked]] = False
        ok = wp.array(ok_np.astype(np.int32), dtype=wp.int32, device=dev)
    tubes = lattice.tubes
    n_tubes = len(tubes)
    geo = {name: wp.zeros(n_tubes, dtype=dtype, device=dev) for name, dtype in (
        ("power", wp.float64), ("across", wp.float64), ("turns", wp.int32), ("valid", wp.int32))}
    tubes_wp = wp.array(tubes, dtype=wp.vec3i, device=dev)
    runtime.launch(K.tube_geometry, n_tubes, [
        wp.array(hits, dtype=wp.vec3d, device=dev), out["exit_point"], out["direction"], out["distance"],
        ok, tubes_wp, wp.vec3d(*k_hat), geo["power"], geo["across"], geo["turns"], geo["valid"]], dev)
    valid = geo["valid"].numpy().astype(bool)
    power, across = geo["power"].numpy(), geo["across"].numpy()
    corner = tubes[valid].ravel()
    sum_p = np.bincount(corner, np.repeat(power[valid], 3), minlength=n_rays)
    sum_a = np.bincount(corner, np.repeat(across[valid], 3), minlength=n_rays)
    with np.errstate(divide="ignore", invalid="ignore"):
        amp = np.where(sum_a > 0, np.sqrt(sum_p / sum_a), 0.0)
    d = out["direction"].numpy()
    arrays = {name: out[name] for name in ("chart", "path", "distance")}
    arrays["amplitude"] = wp.array(amp[:, None] * out["polar"].numpy(), dtype=wp.vec3d, device=dev)
    # PO's longitudinal part: -(d . (n x h_hat)) d per unit amplitude (E_r = -(n x h_hat) across d)
    ell = np.sum(d * np.cross(normals, wave.h_hat), axis=1)
    arrays["longitudinal"] = wp.array((-amp * ell)[:, None] * d, dtype=wp.vec3d, device=dev)
    arrays["tubes"] = tubes_wp
    arrays["turns"] = geo["turns"]
    buckets = bucket_tubes(out["chart"].numpy(), tubes, valid)
    return GeometricWave(dev, focus, float(radius), wave.k, arrays, buckets, n_rays, n_tubes,
                         int(lit.sum()), int((lit & ~ok_np).sum()), int(valid.sum()),
                         int((geo["turns"].numpy()[valid] > 0).sum()))
