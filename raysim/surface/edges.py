"""The free edges of a reflector mesh as quadrature lines: points, local plate frame, lengths.

Frame and units of docs/physics.md (reflector frame, metres). A free edge is a mesh edge used by one
face only (:func:`raysim.surface.quadrature.free_edges`): the rim, the edges of a central hole and
every panel edge beside a gap. Each is integrated by a Gauss-Legendre rule of n points, n the
edge's length over ``spacing`` (at least ``n_min``). Where the reflector has a smooth surface
the points lie on it: an edge whose two ends sit at one radius from the axis is the circle
through them (the rim and the ring edges, as :func:`raysim.surface.quadrature.boundary_arcs` treats
them), any other edge is the straight segment between its ends in the aperture plane, lifted
onto the surface; tangent and normal come from the surface. A mesh loaded from a file keeps
its straight edges, with the face's own normal.

At each point the local wedge is a thin plate (exterior angle 2 pi): the tangent t of the
edge, the normal n of the surface (towards +z, the dish's front) and the direction ``inward``
in the plate's tangent plane, normal to the edge, pointing into the plate (towards the face's
opposite vertex).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from raysim.errors import RaysimError
from raysim.surface.mesh import Reflector
from raysim.surface.quadrature import free_edges, gauss_legendre01

EDGE_SETS = ("rim", "all")
RIM_TOLERANCE = 1e-3  # an edge is on the rim when both ends lie within this fraction of r_max


@dataclass(frozen=True)
class Edges:
    """Quadrature points along free edges (reflector frame, m).

    ``points`` (N, 3); ``tangent``, ``normal``, ``inward`` (N, 3) unit vectors (see the module
    docstring); ``length`` (N,) the Gauss weight times the edge's arc length (m); ``facet``
    (N, 3) a point on the face's flat facet just inside the edge and ``face`` (N,) the face,
    for the shadow test; ``rim`` (N,) True on the outer rim; ``share`` (N, 2) the arc-length
    offsets (m, along ``tangent``) of the start and end of the part of its edge a point stands
    for (the Gauss rule's weights laid end to end), so the shares of one edge tile it.
    """

    points: NDArray[np.float64]
    tangent: NDArray[np.float64]
    normal: NDArray[np.float64]
    inward: NDArray[np.float64]
    length: NDArray[np.float64]
    facet: NDArray[np.float64]
    face: NDArray[np.int64]
    rim: NDArray[np.bool_]
    share: NDArray[np.float64] | None = None

    def __len__(self) -> int:
        return len(self.face)


def _unit(v: NDArray) -> NDArray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


#: a spacing rule per edge: (chord midpoints (E, 3), unit chord directions (E, 3), lengths (E,))
#: -> spacing (E,) in m
SpacingRule = Callable[[NDArray, NDArray, NDArray], NDArray]


def edge_quadrature(reflector: Reflector, spacing: float | SpacingRule, which: str = "all",
                    n_min: int = 3, curve: bool = True) -> Edges:
    """Gauss points about ``spacing`` (m) apart along the free edges of ``reflector``.

    ``spacing`` is one length for every edge, or a rule giving each mesh edge its own.

    ``which`` is ``rim`` (the outer rim alone: both ends within 0.1 % of the largest radius
    from the axis) or ``all`` (every free edge: rim, hole and panel gaps). ``curve`` False
    keeps every edge straight (tests against straight-edge solutions).
    """
    if which not in EDGE_SETS:
        raise RaysimError(f"unknown edge set {which!r}: use rim or all")
    if not callable(spacing) and not spacing > 0:
        raise RaysimError(f"edge spacing must be > 0 m, got {spacing:g}")
    v = reflector.vertices
    b, c, a, face = free_edges(reflector.faces)
    r = np.hypot(v[:, 0], v[:, 1])
    r_max = float(r.max()) if len(r) else 0.0
    on_rim = (r[b] >= r_max * (1.0 - RIM_TOLERANCE)) & (r[c] >= r_max * (1.0 - RIM_TOLERANCE))
    if which == "rim":
        b, c, a, face, on_rim = b[on_rim], c[on_rim], a[on_rim], face[on_rim], on_rim[on_rim]
    arc = np.zeros(len(b), dtype=bool)
    if reflector.arc_edges and curve:
        rb, rc = r[b], r[c]
        arc = (rb > 0) & (np.abs(rb - rc) <= 1e-9 * np.maximum(rb, rc))
    dphi = np.angle(np.exp(1j * (np.arctan2(v[c, 1], v[c, 0]) - np.arctan2(v[b, 1], v[b, 0]))))
    length = np.where(arc, 0.5 * (r[b] + r[c]) * np.abs(dphi),
                      np.linalg.norm(v[c] - v[b], axis=1))
    if callable(spacing):
        chord = v[c] - v[b]
        size = np.linalg.norm(chord, axis=1)
        h = np.asarray(spacing(0.5 * (v[b] + v[c]), chord / np.maximum(size, 1e-300)[:, None], length),
                       dtype=np.float64)
        if not np.all(h > 0):
            raise RaysimError("edge spacing rule gave a spacing <= 0 m")
    else:
        h = spacing
    n = np.maximum(n_min, np.ceil(length / h)).astype(np.int64)
    parts = []
    for order in np.unique(n):
        sel = np.flatnonzero(n == order)
        parts.append(_edge_points(reflector, b[sel], c[sel], a[sel], face[sel], arc[sel], dphi[sel],
                                  on_rim[sel], int(order)))
    if not parts:
        empty = np.zeros((0, 3))
        return Edges(empty, empty, empty, empty, np.zeros(0), empty, np.zeros(0, dtype=np.int64),
                     np.zeros(0, dtype=bool), np.zeros((0, 2)))
    return Edges(*(np.concatenate([getattr(p, f) for p in parts]) for f in Edges.__dataclass_fields__))


def _edge_points(refl: Reflector, b, c, a, face, arc, dphi, on_rim, order: int) -> Edges:
    """Points, frames and weights of edges that share one Gauss order."""
    v = refl.vertices
    u, w = gauss_legendre01(order)
    E, P = len(b), len(u)
    vb, vc, va = v[b][:, None, :], v[c][:, None, :], v[a][:, None, :]
    chord = vb + u[None, :, None] * (vc - vb)  # (E, P, 3) on the straight facet edge
    if refl.surface is not None:
        # aperture-plane curve (x, y)(u) and its derivative: arc or straight segment
        rho = 0.5 * (np.hypot(v[b, 0], v[b, 1]) + np.hypot(v[c, 0], v[c, 1]))[:, None]
        phi = np.arctan2(v[b, 1], v[b, 0])[:, None] + u[None, :] * dphi[:, None]
        xa, ya = rho * np.cos(phi), rho * np.sin(phi)
        dxa, dya = -ya * dphi[:, None], xa * dphi[:, None]
        xs, ys = chord[..., 0], chord[..., 1]
        dxs = np.broadcast_to((v[c, 0] - v[b, 0])[:, None], (E, P))
        dys = np.broadcast_to((v[c, 1] - v[b, 1])[:, None], (E, P))
        m = arc[:, None]
        x, y = np.where(m, xa, xs).ravel(), np.where(m, ya, ys).ravel()
        dx, dy = np.where(m, dxa, dxs).ravel(), np.where(m, dya, dys).ravel()
        panel = refl.surface_panel(np.repeat(face, P))
        z = refl.surface.height(x, y, panel)
        hx, hy = refl.surface.slope(x, y, panel)
        points = np.column_stack([x, y, z])
        deriv = np.column_stack([dx, dy, hx * dx + hy * dy])
        normal = refl.surface.normal(x, y, panel)
    else:
        points = chord.reshape(-1, 3)
        deriv = np.repeat((v[c] - v[b]), P, axis=0)
        f = refl.vertices[refl.faces[face]]
        facet_n = _unit(np.cross(f[:, 1] - f[:, 0], f[:, 2] - f[:, 0]))
        facet_n *= np.where(facet_n[:, 2:] < 0, -1.0, 1.0)
        normal = np.repeat(facet_n, P, axis=0)
    speed = np.linalg.norm(deriv, axis=1)
    tangent = deriv / speed[:, None]
    inward = _unit(np.cross(normal, tangent))
    towards = (np.repeat(va.reshape(-1, 3), P, axis=0) - points)
    inward *= np.where(np.sum(inward * towards, axis=1) < 0, -1.0, 1.0)[:, None]
    facet = (chord + 1e-3 * (va - chord)).reshape(-1, 3)
    ends = np.cumsum(w)
    share = np.column_stack([np.tile(ends - w - u, E), np.tile(ends - u, E)]) * speed[:, None]
    return Edges(points, tangent, normal, inward, speed * np.tile(w, E), facet, np.repeat(face, P),
                 np.repeat(on_rim, P), share)
