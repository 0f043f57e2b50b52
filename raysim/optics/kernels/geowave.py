"""Warp kernels of the go+edge engine's geometric wave (see :mod:`raysim.optics.geowave`).

Time convention exp(+j w t), SI units, reflector frame; fields as (Re x, y, z, Im x, y, z).

- :func:`reflect_rays`: each lit ray of the lattice reflected (float64) at its hit, followed to
  where it enters the probe sphere: the point Q, its Lambert chart coordinate, the unit ray
  direction, the optical path from the incident wavefront through the hit to Q (m) and the
  reflected polarisation E_r = -e + 2 (n . e) n of the unit incident E (PEC).
- :func:`tube_geometry`: per tube, its incident and exit cross-sections (the divergence) and
  the caustics it crosses before the sphere.
- :func:`geometric_field`: the geometric wave at each field point. The point's chart
  coordinate is looked up in a bucket grid of the tubes (each bucket lists, in ascending order,
  the tubes whose chart bounding box meets it); every tube containing it adds its field, so
  folds add. Within a tube the ray amplitudes (vector, real), the paths and the distances from
  the reflection points are interpolated barycentrically in the chart (the path along the
  sphere is smooth: an exact constant for the ideal paraboloid, whose wavefront is the
  sphere; carrying each ray's path on along its direction would add the chord's sag); the
  phase factor is
  exp(-j k L) times j per caustic the tube crossed. The field carries the near-field factors
  of the free-space Green's function at its reflection point, a = 1 - j u - u^2 on the
  transverse part and a - b = 2 j u + 2 u^2 on PO's longitudinal part (u = 1 / (k s), s the
  distance from the reflection point): PO's stationary-phase value, to which the edge
  currents' reflection-boundary jump is matched. A point on an edge shared by two tubes
  belongs to exactly one (the edge functions are computed once per edge, in a canonical
  direction, and ties go to the tube for which the edge is a top-left edge).
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.f64 import F64_HALF, F64_ONE, F64_TWO, F64_ZERO
from raysim.optics.kernels.go import cross2, lambert, sphere_entry
from raysim.optics.kernels.radiation import cis, vec6d

wp.set_module_options({"enable_backward": False})


@wp.kernel
def reflect_rays(
    hits: wp.array(dtype=wp.vec3d),
    normals: wp.array(dtype=wp.vec3d),
    k_hat: wp.vec3d,
    e_hat: wp.vec3d,
    focus: wp.vec3d,
    radius: wp.float64,
    ok: wp.array(dtype=wp.int32),
    chart: wp.array(dtype=wp.vec2d),
    exit_point: wp.array(dtype=wp.vec3d),
    direction: wp.array(dtype=wp.vec3d),
    path: wp.array(dtype=wp.float64),
    distance: wp.array(dtype=wp.float64),
    polar: wp.array(dtype=wp.vec3d),
    offset: int,
):
    """Per lit ray: where it enters the sphere (Q, chart), its direction, path and polarisation.

    path = k_hat . hit + |Q - hit| (m): the phase exp(-j k path) of the incident wave carried
    to Q; distance = |Q - hit|. ok[i] is cleared when the ray misses the sphere.
    """
    i = wp.tid() + offset
    if ok[i] == 0:
        return
    n = normals[i]
    h = hits[i]
    r, s = sphere_entry(h, n, k_hat, focus, radius)
    if s <= F64_ZERO:
        ok[i] = 0
        return
    q = h + s * r
    exit_point[i] = q
    chart[i] = lambert((q - focus) / radius)
    direction[i] = r
    path[i] = wp.dot(k_hat, h) + s
    distance[i] = s
    polar[i] = F64_TWO * wp.dot(n, e_hat) * n - e_hat


@wp.func
def caustics_before(c0: wp.float64, c1: wp.float64, c2: wp.float64, s_end: wp.float64) -> int:
    """Roots in (0, s_end) of A(s) = c0 + c1 s + c2 s^2 (a double root counts twice)."""
    scale = wp.abs(c0) + wp.abs(c1) * s_end + wp.abs(c2) * s_end * s_end
    count = int(0)
    if wp.abs(c2) * s_end * s_end <= wp.float64(1e-12) * scale:
        if c1 != F64_ZERO:
            r = -c0 / c1
            if r > F64_ZERO and r < s_end:
                count = 1
        return count
    disc = c1 * c1 - wp.float64(4.0) * c2 * c0
    if wp.abs(disc) <= wp.float64(1e-9) * (c1 * c1 + wp.abs(wp.float64(4.0) * c2 * c0)):
        r = -c1 / (F64_TWO * c2)
        if r > F64_ZERO and r < s_end:
            count = 2
        return count
    if disc > F64_ZERO:
        sq = wp.sqrt(disc)
        r1 = (-c1 - sq) / (F64_TWO * c2)
        r2 = (-c1 + sq) / (F64_TWO * c2)
        if r1 > F64_ZERO and r1 < s_end:
            count += 1
        if r2 > F64_ZERO and r2 < s_end:
            count += 1
    return count


@wp.kernel
def tube_geometry(
    hits: wp.array(dtype=wp.vec3d),
    exit_point: wp.array(dtype=wp.vec3d),
    direction: wp.array(dtype=wp.vec3d),
    distance: wp.array(dtype=wp.float64),
    ok: wp.array(dtype=wp.int32),
    tubes: wp.array(dtype=wp.vec3i),
    k_hat: wp.vec3d,
    power: wp.array(dtype=wp.float64),
    across: wp.array(dtype=wp.float64),
    turns: wp.array(dtype=wp.int32),
    valid: wp.array(dtype=wp.int32),
    offset: int,
):
    """Per tube whose three rays reach the sphere: its incident cross-section (power, m^2),
    its cross-section normal to the mean ray where it meets the sphere (m^2) and the caustics
    it crosses on the way: roots in (0, s_end) of A(s) = 1/2 [(h1 - h0 + s (d1 - d0)) x
    (h2 - h0 + s (d2 - d0))] . d_mean, a quadratic in the distance s along the rays."""
    t = wp.tid() + offset
    tri = tubes[t]
    if ok[tri[0]] == 0 or ok[tri[1]] == 0 or ok[tri[2]] == 0:
        return
    valid[t] = 1
    h0 = hits[tri[0]]
    dh1 = hits[tri[1]] - h0
    dh2 = hits[tri[2]] - h0
    d0 = direction[tri[0]]
    dd1 = direction[tri[1]] - d0
    dd2 = direction[tri[2]] - d0
    dm = wp.normalize(d0 + direction[tri[1]] + direction[tri[2]])
    power[t] = F64_HALF * wp.abs(wp.dot(wp.cross(dh1, dh2), k_hat))
    q0 = exit_point[tri[0]]
    across[t] = F64_HALF * wp.abs(wp.dot(wp.cross(exit_point[tri[1]] - q0, exit_point[tri[2]] - q0), dm))
    c0 = F64_HALF * wp.dot(wp.cross(dh1, dh2), dm)
    c1 = F64_HALF * wp.dot(wp.cross(dh1, dd2) + wp.cross(dd1, dh2), dm)
    c2 = F64_HALF * wp.dot(wp.cross(dd1, dd2), dm)
    s_end = (distance[tri[0]] + distance[tri[1]] + distance[tri[2]]) / wp.float64(3.0)
    turns[t] = caustics_before(c0, c1, c2, s_end)


@wp.func
def top_left(d: wp.vec2d) -> bool:
    """The tie rule: a point on an edge traversed along d (counter-clockwise) belongs to it."""
    return d[1] < F64_ZERO or (d[1] == F64_ZERO and d[0] < F64_ZERO)


@wp.func
def cis_signed(x: wp.float64, table: wp.array(dtype=wp.vec2d)) -> wp.vec2d:
    """(cos x, sin x) for any x within the phase range of :func:`cis`."""
    c = cis(wp.abs(x), table)
    if x < F64_ZERO:
        c = wp.vec2d(c[0], -c[1])
    return c


@wp.func
def edge_function(ia: int, ib: int, chart: wp.array(dtype=wp.vec2d), x: wp.vec2d, sense: wp.float64):
    """The counter-clockwise edge function of the tube edge ia -> ib at x and its direction,
    computed from the lower ray index to the higher one whatever the tube's winding."""
    lo = wp.min(ia, ib)
    hi = wp.max(ia, ib)
    d = chart[hi] - chart[lo]
    e = cross2(d, x - chart[lo])
    sign = sense
    if ia != lo:
        sign = -sense
    return sign * e, sign * d


@wp.kernel
def geometric_field(
    point_chart: wp.array(dtype=wp.vec2d),
    chart: wp.array(dtype=wp.vec2d),
    path: wp.array(dtype=wp.float64),
    distance: wp.array(dtype=wp.float64),
    amplitude: wp.array(dtype=wp.vec3d),
    longitudinal: wp.array(dtype=wp.vec3d),
    tubes: wp.array(dtype=wp.vec3i),
    turns: wp.array(dtype=wp.int32),
    bucket_start: wp.array(dtype=wp.int32),
    bucket_tubes: wp.array(dtype=wp.int32),
    origin: wp.vec2d,
    inv_size: wp.float64,
    nx: int,
    ny: int,
    k: wp.float64,
    table: wp.array(dtype=wp.vec2d),
    E: wp.array2d(dtype=wp.float64),
    offset: int,
):
    """E (6, n) of the geometric wave at each field point on the sphere, given by its chart
    coordinate (module docstring)."""
    i = wp.tid() + offset
    x = point_chart[i]
    fx = (x[0] - origin[0]) * inv_size
    fy = (x[1] - origin[1]) * inv_size
    acc = vec6d()
    if fx >= F64_ZERO and fy >= F64_ZERO and fx < wp.float64(nx) and fy < wp.float64(ny):
        cell = int(wp.floor(fy)) * nx + int(wp.floor(fx))
        for m in range(bucket_start[cell], bucket_start[cell + 1]):
            t = bucket_tubes[m]
            tri = tubes[t]
            area = cross2(chart[tri[1]] - chart[tri[0]], chart[tri[2]] - chart[tri[0]])
            if area == F64_ZERO:
                continue
            sense = F64_ONE
            if area < F64_ZERO:
                sense = -F64_ONE
            e01, d01 = edge_function(tri[0], tri[1], chart, x, sense)
            e12, d12 = edge_function(tri[1], tri[2], chart, x, sense)
            e20, d20 = edge_function(tri[2], tri[0], chart, x, sense)
            if e01 < F64_ZERO or e12 < F64_ZERO or e20 < F64_ZERO:
                continue
            if (e01 == F64_ZERO and not top_left(d01)) or (e12 == F64_ZERO and not top_left(d12)) \
                    or (e20 == F64_ZERO and not top_left(d20)):
                continue
            total = e01 + e12 + e20
            w0 = e12 / total
            w1 = e20 / total
            w2 = e01 / total
            a = w0 * amplitude[tri[0]] + w1 * amplitude[tri[1]] + w2 * amplitude[tri[2]]
            b = w0 * longitudinal[tri[0]] + w1 * longitudinal[tri[1]] + w2 * longitudinal[tri[2]]
            L = w0 * path[tri[0]] + w1 * path[tri[1]] + w2 * path[tri[2]]
            s = w0 * distance[tri[0]] + w1 * distance[tri[1]] + w2 * distance[tri[2]]
            ph = cis_signed(k * L, table)
            c = wp.vec2d(ph[0], -ph[1])  # exp(-j k L)
            n_turn = turns[t] % 4  # j per caustic crossed
            for _q in range(n_turn):
                c = wp.vec2d(-c[1], c[0])
            # the Green's function's near-field factors at the reflection point: a on the
            # transverse field, a - b = 2 j u + 2 u^2 on the longitudinal one (u = 1 / (k s))
            u = F64_ONE / (k * s)
            ca = wp.vec2d(c[0] * (F64_ONE - u * u) + c[1] * u, c[1] * (F64_ONE - u * u) - c[0] * u)
            cb = wp.vec2d(F64_TWO * u * (c[0] * u - c[1]), F64_TWO * u * (c[1] * u + c[0]))
            e_re = ca[0] * a + cb[0] * b
            e_im = ca[1] * a + cb[1] * b
            acc += vec6d(e_re[0], e_re[1], e_re[2], e_im[0], e_im[1], e_im[2])
    for comp in range(6):
        E[comp, i] = acc[comp]
