"""A loaded mesh's departure from its fitted paraboloid, as a smooth surface piece by piece.

A mesh file gives the dish as flat facets. Their area-weighted vertex normals are off the
surface they sample by 0.1 to 0.3 deg whatever the mesh's fineness, and GO's intensity, which
follows the normals' derivatives, carried that error into the ratio FA: 2.1 times FA's own RMS
on a 25 m dish with two bumps, against 0.07 for the same triangulation given as a scene. So a
loaded mesh is the fitted paraboloid z = r^2 / (4F) plus this departure d(x, y), the vertices'
z less the paraboloid's, interpolated over each connected piece (a panel: nothing is
interpolated across a gap). The paraboloid's curvature, which dominates, is then exact, and
what is interpolated is the small departure alone, so its errors are a share of the
departure's.

The interpolation: each vertex has the least-squares quadratic through its neighbours up to
two edges away on the mesh's own faces (its gradient O(h^2) for a smooth d; a plane where a
vertex has too few); at a point, the three corners' quadratics and their gradients are
blended with the point's barycentric weights in its face. Normals are then continuous, and
so, to O(h), is their derivative, the curvature that GO's intensity follows.

Frame and units of docs/physics.md: reflector frame (vertex at the origin, axis +z), metres;
d in metres along z, its gradient dimensionless.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.surface.deformation import Deformation

Array = NDArray[np.float64]

#: a vertex's quadratic fit (5 unknowns) and plane (2) need this many neighbours (a margin,
#: so that a row of neighbours along a rim does not fix the curvature across it)
FIT_NEIGHBOURS = {5: 8, 2: 2}
#: ... and its normal matrix's condition, in units of the neighbours' own spacing, below this
FIT_CONDITION = 1e8


class MeshDeparture(Deformation):
    """d(x, y) (m, along z) of a loaded mesh, blended over its own triangles.

    ``xy`` (n, 2) the vertices' aperture coordinates (m), ``departure`` (n,) their z less the
    paraboloid's (m), ``faces`` (m, 3) the mesh's triangles (vertex indices). Calls take as
    ``panel`` the face each point lies on (:meth:`raysim.surface.mesh.Reflector.surface_panel`:
    the optics know it, so nothing is searched); a point a little off its face (a ray's
    Newton steps) takes the face's blend continued. Without faces (None, or -1) each point
    takes the face of its nearest vertex, which beside a gap may be the neighbouring panel's.
    """

    def __init__(self, xy: ArrayLike, departure: ArrayLike, faces: ArrayLike) -> None:
        self.xy = np.asarray(xy, dtype=np.float64)
        self.departure = np.asarray(departure, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.flat = not np.any(self.departure[np.unique(self.faces)]) if len(self.faces) else True

    def __getstate__(self) -> dict:
        # what is derived is derived again where needed (Dask workers)
        return {k: getattr(self, k) for k in ("xy", "departure", "faces", "flat")}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)

    def describe(self) -> str:
        return "the mesh's departure from its paraboloid"

    def __call__(self, x: ArrayLike, y: ArrayLike, panel: ArrayLike | None = None) -> Array:
        return self._evaluate(x, y, panel, slope=False)[0]

    def gradient(self, x: ArrayLike, y: ArrayLike, panel: ArrayLike | None = None) -> tuple[Array, Array]:
        _, gx, gy = self._evaluate(x, y, panel, slope=True)
        return gx, gy

    def _evaluate(self, x: ArrayLike, y: ArrayLike, panel: ArrayLike | None,
                  slope: bool) -> tuple[Array, Array, Array]:
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        shape = x.shape
        if self.flat or x.size == 0:
            return np.zeros(shape), np.zeros(shape), np.zeros(shape)
        q = np.column_stack([x.ravel(), y.ravel()])
        face = self._faces_of(q, panel, shape)
        corners = self.faces[face]
        weights = _barycentric(self.xy[corners], q)
        # each corner's own quadratic about it, at the point, blended: the curvature is then
        # the corners' blended too (blending the corners' gradients alone made it constant on
        # a face and jump at its edges, which go+edge's rays, finer than the faces, saw: 0.245
        # of FA's RMS against the analytic dish at 0.15 m triangles; now 0.174)
        c = self.vertex_jet[corners]  # (n, 3, 5): the corners' Taylor coefficients
        dx, dy = (q[:, None, :] - self.xy[corners]).transpose(2, 0, 1)
        gx = c[..., 0] + c[..., 2] * dx + c[..., 3] * dy
        gy = c[..., 1] + c[..., 3] * dx + c[..., 4] * dy
        # d_k + g.delta + delta.H.delta / 2, as delta.(g + grad q_k) / 2
        own = self.departure[corners] + 0.5 * (dx * (c[..., 0] + gx) + dy * (c[..., 1] + gy))
        value = np.einsum("nk,nk->n", weights, own).reshape(shape)
        if not slope:
            return value, np.zeros(shape), np.zeros(shape)
        return (value, np.einsum("nk,nk->n", weights, gx).reshape(shape),
                np.einsum("nk,nk->n", weights, gy).reshape(shape))

    def _faces_of(self, q: Array, panel: ArrayLike | None, shape: tuple) -> NDArray[np.int64]:
        if panel is None:
            return self._nearest_face(q)
        face = np.broadcast_to(np.asarray(panel, dtype=np.int64), shape).ravel().copy()
        lost = (face < 0) | (face >= len(self.faces))
        if lost.any():
            face[lost] = self._nearest_face(q[lost])
        return face

    def _nearest_face(self, q: Array) -> NDArray[np.int64]:
        _, index = self._tree.query(q)
        return self._vertex_face[self._used[index]]

    @cached_property
    def _used(self) -> NDArray[np.int64]:
        """The vertices on faces (the others have no face to blend over)."""
        return np.unique(self.faces)

    @cached_property
    def vertex_jet(self) -> Array:
        """(n, 5) d's Taylor coefficients at the vertices (:func:`vertex_jets`)."""
        return vertex_jets(self.xy, self.departure, self.faces)

    @cached_property
    def _vertex_face(self) -> NDArray[np.int64]:
        return vertex_faces(self.faces, len(self.xy))

    @cached_property
    def _tree(self):
        from scipy.spatial import cKDTree

        return cKDTree(self.xy[self._used])


def vertex_faces(faces: NDArray[np.int64], n_vertices: int) -> NDArray[np.int64]:
    """(n,) the first face holding each vertex, -1 for a vertex on none."""
    face = np.full(n_vertices, -1, dtype=np.int64)
    face[faces[::-1].ravel()] = np.repeat(np.arange(len(faces))[::-1], 3)
    return face


def _barycentric(corners: Array, q: Array) -> Array:
    """(n, 3) barycentric coordinates of points ``q`` (n, 2) in triangles ``corners`` (n, 3, 2).
    (scipy's ``Delaunay.transform`` computes every simplex's at once, 0.2 s for 500 slivers of a
    float32 mesh's hull.)"""
    a, b, c = corners[:, 0] - corners[:, 2], corners[:, 1] - corners[:, 2], q - corners[:, 2]
    det = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    la = (c[:, 0] * b[:, 1] - c[:, 1] * b[:, 0]) / det
    lb = (a[:, 0] * c[:, 1] - a[:, 1] * c[:, 0]) / det
    return np.column_stack([la, lb, 1.0 - la - lb])


def vertex_gradients(xy: Array, value: Array, faces: NDArray[np.int64]) -> Array:
    """(n, 2) gradient of ``value`` at each vertex (:func:`vertex_jets`)."""
    return vertex_jets(xy, value, faces)[:, :2]


def vertex_jets(xy: Array, value: Array, faces: NDArray[np.int64]) -> Array:
    """(n, 5) Taylor coefficients of ``value`` about each vertex: the gradient (dimensionless)
    and the second derivatives h_xx, h_xy, h_yy (1/m) of the weighted least-squares quadratic
    through the vertex (its value held) and its neighbours up to two edges away on ``faces``;
    the plane (no curvature) where a vertex has too few neighbours (:data:`FIT_NEIGHBOURS`)
    or they fix the quadratic badly; zero for a vertex on no face. (A cubic fit gives better
    second derivatives on exact data, but draws the float32 rounding of a binary STL into
    them: a 25 m dish's GO FA went from 0.093 to 0.21 of its RMS off the equation.)"""
    from scipy.sparse import coo_matrix

    n = len(xy)
    out = np.zeros((n, 5))
    if len(faces) == 0:
        return out
    rows = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]])
    cols = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
    ring = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n)).tocsr()
    ring = ring + ring.T
    two = (ring + ring @ ring).tocoo()
    keep = two.row != two.col
    i, j = two.row[keep], two.col[keep]
    d = xy[j] - xy[i]
    # each vertex's own length scale (its neighbours' RMS distance) keeps the normal matrix
    # near unit condition whatever the mesh's units
    dist2 = np.einsum("nc,nc->n", d, d)
    count = np.bincount(i, minlength=n)
    scale = np.sqrt(np.bincount(i, weights=dist2, minlength=n) / np.maximum(count, 1))
    u, v = d[:, 0] / scale[i], d[:, 1] / scale[i]
    w = 1.0 / (1.0 + u * u + v * v)  # nearer neighbours weigh more
    basis = [u, v, u * u, u * v, v * v]  # columns apart: stacking 2 M rows cost a second
    weighted = [w * b for b in basis]
    rhs_value = value[j] - value[i]
    k = len(basis)
    normal = np.zeros((n, k, k))
    rhs = np.zeros((n, k))
    for a in range(k):
        rhs[:, a] = np.bincount(i, weights=weighted[a] * rhs_value, minlength=n)
        for b in range(a, k):
            normal[:, a, b] = normal[:, b, a] = np.bincount(i, weights=weighted[a] * basis[b], minlength=n)
    left = count >= 2
    for size in (5, 2):  # quadratic, plane: the richer fit each vertex fixes
        fits = np.flatnonzero(left & (count >= FIT_NEIGHBOURS[size]))
        fits = fits[_conditioned(normal[fits][:, :size, :size])]
        if len(fits):
            block = normal[fits][:, :size, :size]
            out[fits, :size] = np.linalg.solve(block, rhs[fits][:, :size, None])[..., 0]
            left[fits] = False
    unit = np.where(scale > 0, scale, 1.0)[:, None]
    # back to metres (u = dx / scale); the u^2, v^2 coefficients are half the second derivatives
    return out * np.array([1.0, 1.0, 2.0, 1.0, 2.0]) / unit ** np.array([1, 1, 2, 2, 2])


def _conditioned(normal: Array) -> NDArray[np.bool_]:
    """Which symmetric normal matrices (n, k, k) have a condition under
    :data:`FIT_CONDITION`."""
    if len(normal) == 0:
        return np.zeros(0, dtype=bool)
    eig = np.linalg.eigvalsh(normal)
    return eig[:, 0] > eig[:, -1] / FIT_CONDITION
