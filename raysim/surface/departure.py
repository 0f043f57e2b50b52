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

The interpolation: each vertex's gradient of d is the least-squares quadratic through its
neighbours up to two edges away on the mesh's own faces (O(h^2) for a smooth d; linear where
a vertex has too few); d and its gradient are then blended linearly over the mesh's own
triangles (barycentric weights). Normals are then continuous, and their derivatives, which
GO's intensity follows, err by O(h) of the departure's curvature; heights by O(h^2 kappa) of
the departure, far below a wavelength (0.3 um for 100 um bumps of 2 m on 0.15 m triangles).

Frame and units of docs/physics.md: reflector frame (vertex at the origin, axis +z), metres;
d in metres along z, its gradient dimensionless.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.surface.deformation import Deformation

Array = NDArray[np.float64]

#: a vertex's quadratic fit needs this many neighbours (five unknowns, and a margin so that
#: a row of neighbours along a rim does not fix the curvature across it)
QUADRATIC_NEIGHBOURS = 8
#: ... and its normal matrix's condition, in units of the neighbours' own spacing, below this
QUADRATIC_CONDITION = 1e8


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
        value = np.einsum("nk,nk->n", weights, self.departure[corners]).reshape(shape)
        if not slope:
            return value, np.zeros(shape), np.zeros(shape)
        g = np.einsum("nk,nkc->nc", weights, self.vertex_gradient[corners])
        return value, g[:, 0].reshape(shape), g[:, 1].reshape(shape)

    def _faces_of(self, q: Array, panel: ArrayLike | None, shape: tuple) -> NDArray[np.int64]:
        if panel is None:
            return self._nearest_face(q)
        face = np.broadcast_to(np.asarray(panel, dtype=np.int64), shape).ravel().copy()
        lost = (face < 0) | (face >= len(self.faces))
        if lost.any():
            face[lost] = self._nearest_face(q[lost])
        return face

    def _nearest_face(self, q: Array) -> NDArray[np.int64]:
        used = np.unique(self.faces)
        _, index = self._tree.query(q)
        return self._vertex_face[used[index]]

    @cached_property
    def vertex_gradient(self) -> Array:
        """(n, 2) d's gradient at the vertices (:func:`vertex_gradients`), dimensionless."""
        return vertex_gradients(self.xy, self.departure, self.faces)

    @cached_property
    def _vertex_face(self) -> NDArray[np.int64]:
        return vertex_faces(self.faces, len(self.xy))

    @cached_property
    def _tree(self):
        from scipy.spatial import cKDTree

        return cKDTree(self.xy[np.unique(self.faces)])


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
    """(n, 2) gradient of ``value`` at each vertex: the weighted least-squares quadratic
    through the vertex (its value held) and its neighbours up to two edges away on ``faces``;
    the least-squares plane where the quadratic is not fixed (fewer than
    :data:`QUADRATIC_NEIGHBOURS`, or ill-conditioned); zero for a vertex on no face."""
    from scipy.sparse import coo_matrix

    n = len(xy)
    out = np.zeros((n, 2))
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
    normal = np.zeros((n, 5, 5))
    rhs = np.zeros((n, 5))
    for a in range(5):
        rhs[:, a] = np.bincount(i, weights=weighted[a] * rhs_value, minlength=n)
        for b in range(a, 5):
            normal[:, a, b] = normal[:, b, a] = np.bincount(i, weights=weighted[a] * basis[b], minlength=n)
    quadratic = (count >= QUADRATIC_NEIGHBOURS) & _conditioned(normal)
    if quadratic.any():
        coef = np.linalg.solve(normal[quadratic], rhs[quadratic][..., None])[..., 0]
        out[quadratic] = coef[:, :2]
    plane = np.flatnonzero(~quadratic & (count >= 2))
    plane = plane[_conditioned(normal[plane][:, :2, :2])]
    if len(plane):
        out[plane] = np.linalg.solve(normal[plane][:, :2, :2], rhs[plane][:, :2, None])[..., 0]
    return out / np.where(scale > 0, scale, 1.0)[:, None]


def _conditioned(normal: Array) -> NDArray[np.bool_]:
    """Which symmetric normal matrices (n, k, k) have a condition under
    :data:`QUADRATIC_CONDITION`."""
    if len(normal) == 0:
        return np.zeros(0, dtype=bool)
    eig = np.linalg.eigvalsh(normal)
    return eig[:, 0] > eig[:, -1] / QUADRATIC_CONDITION
