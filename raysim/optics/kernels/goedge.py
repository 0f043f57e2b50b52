"""Warp kernels of the go+edge engine (see :mod:`raysim.optics.goedge`): rays, tubes, edges.

Time convention exp(+j w t), SI units, reflector frame; fields as (Re x, y, z, Im x, y, z).

- :func:`reflect_rays`: each lit ray of the lattice reflected (float64) at its hit, followed to
  where it enters the probe sphere: the point Q, its Lambert chart coordinate, the unit ray
  direction, the optical path from the incident wavefront through the hit to Q (m) and the
  reflected polarisation E_r = -e + 2 (n . e) n of the unit incident E (PEC).
- :func:`geometric_field`: the geometric wave at each field point. The point's chart
  coordinate is looked up in a bucket grid of the tubes (each bucket lists, in ascending order,
  the tubes whose chart bounding box meets it); every tube containing it adds its field, so
  folds add. Within a tube the ray amplitudes (vector, real) are interpolated barycentrically
  in the chart and so is the path, each ray's path first carried to the point along its own
  direction (L_v + d_v . (P - Q_v): second order in the tube's size); the phase factor is
  exp(-j k L) times j per caustic the tube crossed. A point on an edge shared by two tubes
  belongs to exactly one (the edge functions are computed once per edge, in a canonical
  direction, and ties go to the tube for which the edge is a top-left edge).
- :func:`diffraction_pair`: one edge element's field at a point, the fringe currents of
  :mod:`raysim.optics.kernels.ptd` plus PO's end-point current (rows of :data:`ROWS`). The end
  point: E = -eta / (4 pi) exp(-j k R) / R [a p - b (R_hat . p) R_hat] with p = J0 exp(-j k
  k_i . r) * Int (M g . u) / (g^T M g) ds over the element's share of its edge, g the surface
  gradient of the phase (k_i - R_hat) in the tangent plane (t, u), linear in s (g0 + s H e_t,
  H the surface Hessian of the path), M = adj|H| (its small eigenvalue floored at BETA times
  the large one); the integral is done in closed form (:func:`endpoint_integral`): exact for
  the near-singular elements beside a reflection boundary, and the point rule elsewhere.
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.f64 import F64_HALF, F64_ONE, F64_TWO, F64_ZERO
from raysim.optics.kernels.go import lambert, sphere_entry
from raysim.optics.kernels.ptd import ROWS as FRINGE_ROWS
from raysim.optics.kernels.ptd import EdgeElement, fringe_pair, load_edge
from raysim.optics.kernels.radiation import (
    cis,
    electric_bracket,
    green,
    radiation_kernels,
    times,
    vec6d,
)

wp.set_module_options({"enable_backward": False})

# fringe rows (23), then Re J0 (3), Im J0 (3), k_i (3), curvature kappa_tt, tu, uu (3), s_lo, s_hi
ROWS = FRINGE_ROWS + 14
BETA = wp.constant(wp.float64(0.02))  # M = adj|H|: small eigenvalue floored at BETA x the large one
DEFINITE = wp.constant(wp.float64(0.02 / 1.02**2))  # det / tr^2 above it: lambda_min / lambda_max > BETA
TINY = wp.constant(wp.float64(1e-300))


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
def cross2(a: wp.vec2d, b: wp.vec2d) -> wp.float64:
    return a[0] * b[1] - a[1] * b[0]


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
    points: wp.array(dtype=wp.vec3d),
    chart: wp.array(dtype=wp.vec2d),
    exit_point: wp.array(dtype=wp.vec3d),
    direction: wp.array(dtype=wp.vec3d),
    path: wp.array(dtype=wp.float64),
    amplitude: wp.array(dtype=wp.vec3d),
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
    """E (6, n) of the geometric wave at each field point (module docstring)."""
    i = wp.tid() + offset
    x = point_chart[i]
    p = points[i]
    fx = (x[0] - origin[0]) * inv_size
    fy = (x[1] - origin[1]) * inv_size
    acc = vec6d()
    if fx >= F64_ZERO and fy >= F64_ZERO and fx < wp.float64(nx) and fy < wp.float64(ny):
        b = int(wp.floor(fy)) * nx + int(wp.floor(fx))
        for m in range(bucket_start[b], bucket_start[b + 1]):
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
            L = w0 * (path[tri[0]] + wp.dot(direction[tri[0]], p - exit_point[tri[0]])) \
                + w1 * (path[tri[1]] + wp.dot(direction[tri[1]], p - exit_point[tri[1]])) \
                + w2 * (path[tri[2]] + wp.dot(direction[tri[2]], p - exit_point[tri[2]]))
            ph = cis_signed(k * L, table)
            c = wp.vec2d(ph[0], -ph[1])  # exp(-j k L)
            n_turn = turns[t] % 4  # j per caustic crossed
            for _q in range(n_turn):
                c = wp.vec2d(-c[1], c[0])
            acc += vec6d(c[0] * a[0], c[0] * a[1], c[0] * a[2], c[1] * a[0], c[1] * a[1], c[1] * a[2])
    for comp in range(6):
        E[comp, i] = acc[comp]


# --- edge elements: fringe plus PO end point ------------------------------------------------
@wp.struct
class Diffraction:
    """One Gauss point of a free edge: the fringe element of :mod:`raysim.optics.kernels.ptd`
    (``edge``), the end-point moment J0 (complex, prefactor and incident phase included), the
    incident direction k_i, the lit face's curvature in the edge frame (kappa_tt, kappa_tu,
    kappa_uu, 1/m, towards the lit normal) and the element's share s_lo..s_hi of its edge (m,
    along the frame's t, relative to the point)."""

    edge: EdgeElement
    j_re: wp.vec3d
    j_im: wp.vec3d
    k_i: wp.vec3d
    kappa: wp.vec3d
    s_lo: wp.float64
    s_hi: wp.float64


@wp.func
def load_diffraction(src: wp.array2d(dtype=wp.float64), s: int) -> Diffraction:
    e = Diffraction()
    e.edge = load_edge(src, s)
    r = FRINGE_ROWS
    e.j_re = wp.vec3d(src[r, s], src[r + 1, s], src[r + 2, s])
    e.j_im = wp.vec3d(src[r + 3, s], src[r + 4, s], src[r + 5, s])
    e.k_i = wp.vec3d(src[r + 6, s], src[r + 7, s], src[r + 8, s])
    e.kappa = wp.vec3d(src[r + 9, s], src[r + 10, s], src[r + 11, s])
    e.s_lo = src[r + 12, s]
    e.s_hi = src[r + 13, s]
    return e


@wp.func
def definite_integral(a0: wp.float64, b0: wp.float64, htt: wp.float64, htu: wp.float64,
                      det: wp.float64, s_lo: wp.float64, s_hi: wp.float64) -> wp.float64:
    """Int (M g . u) / (g^T M g) ds for M = adj(H), H definite: the numerator is constant,
    (1 / sqrt(det)) [arctan((a0 + htt s) / c)] with c = (htt b0 - htu a0) / sqrt(det)."""
    sd = wp.sqrt(det)
    c = (htt * b0 - htu * a0) / sd
    x1 = a0 + htt * s_lo
    x2 = a0 + htt * s_hi
    return wp.atan2(c * (x2 - x1), c * c + x1 * x2) / sd


@wp.func
def general_integral(a0: wp.float64, b0: wp.float64, htt: wp.float64, htu: wp.float64,
                     huu: wp.float64, s_lo: wp.float64, s_hi: wp.float64) -> wp.float64:
    """The same integral for any H: M = adj|H| with the small eigenvalue floored (pos. def.);
    numerator c0 + c1 s, denominator q(s) = g(s)^T M g(s) (a log and an arctan term)."""
    m = F64_HALF * (htt + huu)
    dd = wp.sqrt(F64_HALF * F64_HALF * (htt - huu) * (htt - huu) + htu * htu)
    l1 = wp.abs(m + dd)
    l2 = wp.abs(m - dd)
    v = wp.vec2d(m + dd - huu, htu)
    if htt < huu:
        v = wp.vec2d(htu, m + dd - htt)
    nv = wp.length(v)
    if nv > F64_ZERO:
        v = v / nv
    else:
        v = wp.vec2d(F64_ONE, F64_ZERO)
    top = wp.max(wp.max(l1, l2), TINY)
    l1 = wp.max(l1, BETA * top)
    l2 = wp.max(l2, BETA * top)
    # adj of |H| = l1 v v^T + l2 w w^T (w = v turned by 90 deg): l2 v v^T + l1 w w^T
    m00 = l2 * v[0] * v[0] + l1 * v[1] * v[1]
    m01 = (l2 - l1) * v[0] * v[1]
    m11 = l2 * v[1] * v[1] + l1 * v[0] * v[0]
    g1 = wp.vec2d(htt, htu)
    mg1 = wp.vec2d(m00 * g1[0] + m01 * g1[1], m01 * g1[0] + m11 * g1[1])
    q2 = wp.dot(g1, mg1)
    h = s_hi - s_lo
    g0 = wp.vec2d(a0, b0)
    mg0 = wp.vec2d(m00 * a0 + m01 * b0, m01 * a0 + m11 * b0)
    q0 = wp.dot(g0, mg0)
    if q2 <= wp.float64(1e-24) * wp.max(q0, TINY):
        return h * mg0[1] / wp.max(q0, TINY)
    det_m = m00 * m11 - m01 * m01
    sd = wp.sqrt(det_m)
    q1 = F64_TWO * wp.dot(g0, mg1)
    gamma = g1[0] * g0[1] - g1[1] * g0[0]
    jmg1 = wp.vec2d(-mg1[1], mg1[0])
    mjmg1_u = m01 * jmg1[0] + m11 * jmg1[1]
    y1 = F64_TWO * q2 * s_lo + q1
    y2 = F64_TWO * q2 * s_hi + q1
    arc = wp.atan2(F64_TWO * sd * gamma * (y2 - y1), wp.float64(4.0) * det_m * gamma * gamma + y1 * y2)
    ga = g0 + s_lo * g1
    gb = g0 + s_hi * g1
    qa = ga[0] * (m00 * ga[0] + m01 * ga[1]) + ga[1] * (m01 * ga[0] + m11 * ga[1])
    qb = gb[0] * (m00 * gb[0] + m01 * gb[1]) + gb[1] * (m01 * gb[0] + m11 * gb[1])
    log_term = mg1[1] / (F64_TWO * q2) * wp.log(wp.max(qb, TINY) / wp.max(qa, TINY))
    return log_term + mjmg1_u / (q2 * sd) * arc


@wp.func
def endpoint_integral(a0: wp.float64, b0: wp.float64, htt: wp.float64, htu: wp.float64,
                      huu: wp.float64, s_lo: wp.float64, s_hi: wp.float64) -> wp.float64:
    """Int (M g . u) / (g^T M g) ds over s_lo..s_hi with g = (a0 + htt s, b0 + htu s)."""
    det = htt * huu - htu * htu
    tr = htt + huu
    if det > DEFINITE * tr * tr:
        return definite_integral(a0, b0, htt, htu, det, s_lo, s_hi)
    return general_integral(a0, b0, htt, htu, huu, s_lo, s_hi)


@wp.func
def endpoint_pair(p: wp.vec3d, e: Diffraction, k: wp.float64, k_inv: wp.float64,
                  table: wp.array(dtype=wp.vec2d)) -> vec6d:
    """E (V/m) at P of the PO end-point current of the element e (module docstring)."""
    f = e.edge
    d = p - f.r
    R2 = wp.dot(d, d)
    inv = F64_ONE / wp.sqrt(R2)
    r_hat = d * inv
    g = e.k_i - r_hat
    rt = wp.dot(r_hat, f.t)
    ru = wp.dot(r_hat, f.x)
    gn = wp.dot(g, f.y)
    htt = (F64_ONE - rt * rt) * inv + gn * e.kappa[0]
    htu = -rt * ru * inv + gn * e.kappa[1]
    huu = (F64_ONE - ru * ru) * inv + gn * e.kappa[2]
    w = endpoint_integral(wp.dot(g, f.t), wp.dot(g, f.x), htt, htu, huu, e.s_lo, e.s_hi)
    return times(electric_bracket(d, inv, inv * k_inv, w * e.j_re, w * e.j_im), green(k, R2, inv, table))


@wp.func
def diffraction_pair(p: wp.vec3d, e: Diffraction, k: wp.float64, k_inv: wp.float64,
                     table: wp.array(dtype=wp.vec2d)) -> vec6d:
    """The edge element's full diffraction at P: fringe plus PO end point (V/m)."""
    return fringe_pair(p, e.edge, k, k_inv, table) + endpoint_pair(p, e, k, k_inv, table)


radiate_diffraction, radiate_diffraction4 = radiation_kernels(load_diffraction, diffraction_pair)
