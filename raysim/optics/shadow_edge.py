"""The lit part of faces an obstacle's shadow crosses, for PO's surface integral.

Frame and units of docs/physics.md (reflector frame, metres). PO's current flows only where the
wave arrives, so the integrand stops at the edge of a shadow. A Gauss rule keeps or drops each
sample whole, an error of the order of a sample's area times the edge's length: with a disk
shadowing a 10 m dish at 0.5 GHz the default quadrature (1.5 samples per wavelength) erred by
1 % in intensity, and 12 % of the FA signal near the shadow of a 1.5 mm bump, converging only
as the sample spacing (0.85 % at 4, 0.18 % at 8 samples per wavelength).

Here each face whose samples are partly lit is divided into four, recursively (:data:`LEVELS`
times); a sub-triangle whose samples and corners are all lit keeps a rule of its own size, one
all in shadow is dropped, and at the last level the shadow's edge is found by bisection along
the sub-triangle's edges (:data:`BISECTIONS` steps) and the lit part, a triangle or a
quadrilateral cut by the straight line between the two crossings, is integrated by a rule of
its own. The edge's error then falls as the square of the finest sub-triangle's size.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from raysim.optics.bvh import ReflectorBVH
from raysim.surface.quadrature import (
    FaceQuadrature,
    Samples,
    concatenated,
    conical_rule,
    lattice_rule,
)

#: a face the shadow's edge crosses is divided into four until its pieces are at most this
#: share of the quadrature's spacing, then the edge is cut straight (the chord of a curved
#: shadow errs by the square of the piece's size: a disk's shadow on a 10 m dish, pieces of an
#: eighth of a metre, left 2.3e-3 m^2 of lit area, a sixteenth 8e-5)
FINEST = 0.5
#: the fewest and the most divisions of a crossed face
LEVELS = (2, 6)
#: bisection steps locating the edge along a sub-triangle's side (2^-20 of its length)
BISECTIONS = 20
#: with obstacles in the beam, points this share of the quadrature's spacing apart along each
#: side of a face (and of its pieces) are tested besides its samples and corners: a leg's shadow
#: narrower than the samples' spacing passed between them all (0.2 m legs on 1 m faces at
#: 0.5 GHz, samples 0.33 m apart: kept or dropped whole, 0.53 % in intensity)
SIDE_STEP = 0.25
#: corners are tested this share of the way towards the sub-triangle's centroid, so a corner on
#: a face's edge is still a point of its own face
INSET = 1e-9
#: the four children of a triangle (barycentric corners, rows) in its own barycentric frame
CHILDREN = np.array([[[1.0, 0.0, 0.0], [0.5, 0.5, 0.0], [0.5, 0.0, 0.5]],
                     [[0.5, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.5, 0.5]],
                     [[0.5, 0.0, 0.5], [0.0, 0.5, 0.5], [0.0, 0.0, 1.0]],
                     [[0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5]]])


def lit_samples(quadrature: FaceQuadrature, samples: Samples, bvh: ReflectorBVH,
                k_hat: NDArray[np.float64]) -> tuple[Samples, int]:
    """The samples of one of the quadrature's chunks that the wave reaches, the faces a
    shadow's edge crosses replaced by their lit part (:func:`lit_part`), and how many samples
    were weighed (the chunk's, less the replaced faces', plus the pieces')."""
    lit = bvh.lit(samples.facet, k_hat, samples.face)
    crossed = crossed_faces(quadrature, samples, lit, bvh, k_hat)
    if not len(crossed):
        return _subset(samples, lit), len(samples)
    part = lit_part(quadrature, crossed, bvh, k_hat)
    replaced = np.isin(samples.face, crossed)
    kept = _joined([_subset(samples, lit & ~replaced), part])
    return kept, len(samples) - int(np.count_nonzero(replaced)) + len(part)


def crossed_faces(quadrature: FaceQuadrature, samples: Samples, lit: NDArray[np.bool_],
                  bvh: ReflectorBVH, k_hat: NDArray[np.float64]) -> NDArray[np.int64]:
    """The faces of a chunk of whole faces' samples (not the arcs') that a shadow's edge
    crosses: their samples and corners are not all lit nor all in shadow (a shadow that clips
    a corner between the samples counts; one that passes between them all does not)."""
    if samples.on_arcs or not len(samples):
        return np.zeros(0, dtype=np.int64)
    faces, index = np.unique(samples.face, return_inverse=True)
    whole = np.broadcast_to(np.eye(3), (len(faces), 3, 3))
    corners = _corners_lit(quadrature, faces, whole, bvh, k_hat)
    side_seen, side_total = _sides_lit(quadrature, faces, whole, bvh, k_hat)
    total = np.bincount(index, minlength=len(faces)) + 3 + side_total
    seen = np.bincount(index, weights=lit, minlength=len(faces)) + corners.sum(axis=1) + side_seen
    return faces[(seen > 0) & (seen < total)]


def lit_part(quadrature: FaceQuadrature, faces: NDArray[np.int64], bvh: ReflectorBVH,
             k_hat: NDArray[np.float64]) -> Samples:
    """Lit samples of ``faces`` (the crossed ones), replacing theirs: see the module."""
    q = quadrature
    face = np.asarray(faces, dtype=np.int64)
    tri = np.broadcast_to(np.eye(3), (len(face), 3, 3)).copy()  # barycentric corners (T, 3, 3)
    need = np.ceil(np.log2(q.edge_length[face] / (FINEST * q.spacing)))
    levels = np.clip(need, *LEVELS).astype(np.int64)               # per face
    kept: list[Samples] = []
    for level in range(1, int(levels.max(initial=0)) + 1):
        face, levels = np.repeat(face, 4), np.repeat(levels, 4)
        tri = np.einsum("cij,tjk->tcik", CHILDREN, tri).reshape(-1, 3, 3)
        samples, owner = _rule_samples(q, face, tri, q.edge_length[face] / 2**level)
        lit = bvh.lit(samples.facet, k_hat, samples.face)
        corners_lit = _corners_lit(q, face, tri, bvh, k_hat)
        side_seen, side_total = _sides_lit(q, face, tri, bvh, k_hat)
        n = len(face)
        seen = np.bincount(owner, weights=lit, minlength=n) + side_seen
        total = np.bincount(owner, minlength=n) + side_total
        all_lit = (seen == total) & corners_lit.all(axis=1)
        dark = (seen == 0) & ~corners_lit.any(axis=1)
        if all_lit.any():
            kept.append(_subset(samples, all_lit[owner]))
        crossed = ~all_lit & ~dark
        last = crossed & (levels == level)
        if last.any():
            kept.append(_cut(q, face[last], tri[last], corners_lit[last], samples, lit, owner,
                             np.flatnonzero(last), bvh, k_hat))
        deeper = crossed & ~last
        face, tri, levels = face[deeper], tri[deeper], levels[deeper]
        if not len(face):
            break
    return _joined(kept)


def _rule_samples(q: FaceQuadrature, face: NDArray[np.int64], tri: NDArray[np.float64],
                  length: NDArray[np.float64]) -> tuple[Samples, NDArray[np.int64]]:
    """Samples of the sub-triangles ``tri`` (T, 3, 3, barycentric corners in their faces) by
    the plan's rule for their size ``length`` (m; a lattice of rules where one would need
    more than n_max points along it), and each sample's sub-triangle."""
    m, n = q.orders_for(length)
    key = m * (q.n_max + 1) + n
    parts, owners = [], []
    for value in np.unique(key):
        sel = np.flatnonzero(key == value)
        rule = lattice_rule(conical_rule(int(value % (q.n_max + 1))), int(value // (q.n_max + 1)))
        bary = np.einsum("pk,tkc->tpc", rule.bary, tri[sel]).reshape(-1, 3)
        share = (np.abs(np.linalg.det(tri[sel]))[:, None] * rule.weights[None, :]).reshape(-1)
        parts.append(q.at(np.repeat(face[sel], rule.size), bary, share))
        owners.append(np.repeat(sel, rule.size))
    return concatenated(parts), np.concatenate(owners)


def _corners_lit(q: FaceQuadrature, face: NDArray[np.int64], tri: NDArray[np.float64],
                 bvh: ReflectorBVH, k_hat: NDArray[np.float64]) -> NDArray[np.bool_]:
    """(T, 3): whether the wave reaches each corner of each sub-triangle (just inside it)."""
    inset = (1.0 - INSET) * tri + INSET * tri.mean(axis=1, keepdims=True)
    return _lit_at(q, np.repeat(face, 3), inset.reshape(-1, 3), bvh, k_hat).reshape(-1, 3)


def _sides_lit(q: FaceQuadrature, face: NDArray[np.int64], tri: NDArray[np.float64],
               bvh: ReflectorBVH, k_hat: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """(lit, tested) per sub-triangle: the points :data:`SIDE_STEP` of the spacing apart along
    its sides, corners excluded (just inside it); none without obstacles in the beam, where
    only the dish's own shadow has an edge, and it is broad."""
    count = len(face)
    if bvh.obstacles is None or not count:
        return np.zeros(count), np.zeros(count, dtype=np.int64)
    refl = q.reflector
    corners = np.einsum("tkj,tjc->tkc", tri, refl.vertices[refl.faces[face]])   # (T, 3, 3) m
    length = np.linalg.norm(corners[:, [1, 2, 0]] - corners, axis=2)            # (T, 3)
    inner = np.maximum(np.ceil(length / (SIDE_STEP * q.spacing)) - 1, 0).astype(np.int64).ravel()
    side = np.repeat(np.arange(3 * count), inner)
    k = np.arange(len(side)) - np.repeat(np.cumsum(inner) - inner, inner)
    t = ((k + 1) / (inner[side] + 1))[:, None]
    start, end = tri.reshape(-1, 3)[side], tri[:, [1, 2, 0]].reshape(-1, 3)[side]
    owner = side // 3
    points = (1.0 - INSET) * (start + t * (end - start)) + INSET * tri.mean(axis=1)[owner]
    lit = _lit_at(q, face[owner], points, bvh, k_hat)
    return (np.bincount(owner, weights=lit, minlength=count),
            np.bincount(owner, minlength=count))


def _lit_at(q: FaceQuadrature, face: NDArray[np.int64], bary: NDArray[np.float64],
            bvh: ReflectorBVH, k_hat: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Whether the wave reaches the facet points ``bary`` (N, 3) of faces ``face``."""
    refl = q.reflector
    facet = np.einsum("nk,nkc->nc", bary, refl.vertices[refl.faces[face]])
    return bvh.lit(facet, k_hat, face)


def _cut(q: FaceQuadrature, face: NDArray[np.int64], tri: NDArray[np.float64],
         corners: NDArray[np.bool_], samples: Samples, lit: NDArray[np.bool_],
         owner: NDArray[np.int64], index: NDArray[np.int64], bvh: ReflectorBVH,
         k_hat: NDArray[np.float64]) -> Samples:
    """The lit part of the last level's crossed sub-triangles: cut straight between the edge's
    crossings of their sides where one or two corners are lit; where the corners agree (a
    shadow narrower than the sub-triangle, or a lit gap in one) their samples are kept or
    dropped one by one."""
    count = corners.sum(axis=1)
    straight = (count == 1) | (count == 2)
    parts: list[Samples] = []
    loose = np.isin(owner, index[~straight])
    if loose.any():
        parts.append(_subset(samples, loose & lit))
    if straight.any():
        face, tri, corners = face[straight], tri[straight], corners[straight]
        # rotate each sub-triangle so that corner 0 is the odd one out (the one lit corner, or
        # the one dark corner); the edge then crosses sides 0-1 and 0-2
        odd = np.where(corners.sum(axis=1) == 1, np.argmax(corners, axis=1),
                       np.argmin(corners, axis=1))
        turn = (odd[:, None] + np.arange(3)[None, :]) % 3
        tri = np.take_along_axis(tri, turn[:, :, None], axis=1)
        apex_lit = np.take_along_axis(corners, turn, axis=1)[:, 0]
        a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
        p = _crossing(q, face, a, b, apex_lit, bvh, k_hat)
        r = _crossing(q, face, a, c, apex_lit, bvh, k_hat)
        # lit apex: the triangle (a, p, r); dark apex: the quadrilateral (p, b, c, r)
        pieces = np.where(apex_lit[:, None, None],
                          np.stack([a, p, r], axis=1), np.stack([p, b, c], axis=1))
        faces = [face]
        second = ~apex_lit
        if second.any():
            pieces = np.concatenate([pieces, np.stack([p[second], c[second], r[second]], axis=1)])
            faces.append(face[second])
        size = q.edge_length[np.concatenate(faces)] * _span(pieces)
        parts.append(_rule_samples(q, np.concatenate(faces), pieces, size)[0])
    return _joined(parts)


def _crossing(q: FaceQuadrature, face: NDArray[np.int64], a: NDArray[np.float64],
              b: NDArray[np.float64], a_lit: NDArray[np.bool_], bvh: ReflectorBVH,
              k_hat: NDArray[np.float64]) -> NDArray[np.float64]:
    """Barycentric point (N, 3) where the shadow's edge crosses the side a-b (a lit and b dark,
    or the reverse as ``a_lit`` says), by bisection."""
    lo, hi = np.zeros(len(face)), np.ones(len(face))
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        same = _lit_at(q, face, a + mid[:, None] * (b - a), bvh, k_hat) == a_lit
        lo, hi = np.where(same, mid, lo), np.where(same, hi, mid)
    t = 0.5 * (lo + hi)
    return a + t[:, None] * (b - a)


def _span(tri: NDArray[np.float64]) -> NDArray[np.float64]:
    """Longest side of barycentric triangles (T, 3, 3) as a share of the reference triangle's
    longest side, bounding the piece's size for its rule."""
    sides = tri[:, [1, 2, 0]] - tri
    return np.abs(sides).max(axis=(1, 2))


def _subset(samples: Samples, mask: NDArray[np.bool_]) -> Samples:
    """The samples where ``mask`` holds."""
    return Samples(samples.points[mask], samples.area[mask], samples.facet[mask],
                   samples.face[mask])


def _joined(parts: list[Samples]) -> Samples:
    """The samples of ``parts`` in one (none: an empty set)."""
    parts = [s for s in parts if len(s)]
    if not parts:
        return Samples(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, dtype=np.int64))
    return concatenated(parts)
