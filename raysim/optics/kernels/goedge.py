"""Warp kernels of the go+edge engine (see :mod:`raysim.optics.goedge`): rays, tubes, edges.

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
- :func:`diffraction_pair`: one edge element's field at a point, the fringe currents of
  :mod:`raysim.optics.kernels.ptd` plus PO's end-point current (rows of :data:`ROWS`). The end
  point: E = -eta / (4 pi) exp(-j k R) / R [a p - b (R_hat . p) R_hat] with p = J0 exp(-j k
  k_i . r) * Int (M g . u) / (g^T M g) ds over the element's share of its edge, g the surface
  gradient of the phase (k_i - R_hat) in the tangent plane (t, u), linear in s (g0 + s H e_t,
  H the surface Hessian of the path), M = adj(H) where H is definite and well conditioned,
  adj|H| (small eigenvalue floored) where not (:func:`endpoint_integral`); the integral is
  in closed form near the zero of g (exact for the near-singular elements beside a reflection
  boundary), the Gauss point value away from it, a smooth blend between.
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.f64 import F64_HALF, F64_ONE, F64_TWO, F64_ZERO
from raysim.optics.kernels.go import lambert, sphere_entry
from raysim.optics.kernels.ptd import ROWS as FRINGE_ROWS
from raysim.optics.kernels.ptd import EdgeElement, fringe_currents, load_edge
from raysim.optics.kernels.radiation import (
    cis,
    electric_bracket,
    green,
    magnetic_bracket,
    radiation_kernels,
    times,
    vec6d,
)

wp.set_module_options({"enable_backward": False})

# fringe rows (23), then Re J0 (3), Im J0 (3), k_i (3), curvature kappa_tt, tu, uu (3), s_lo, s_hi
ROWS = FRINGE_ROWS + 14
BETA = wp.constant(wp.float64(0.25))  # M: small eigenvalue of |H| raised to BETA x the large one
RHO_2 = wp.constant(wp.float64(0.25 / 1.25**2))  # det / tr^2 from which H is definite, l_min / l_max >= BETA
NEAR_1 = wp.constant(wp.float64(0.05))  # h |dg/ds| / |g| below it: the Gauss point value
NEAR_2 = wp.constant(wp.float64(0.3))  # above it: the exact integral of the element's share
TINY = wp.constant(wp.float64(1e-300))
INV_3, INV_5, INV_7, INV_9, INV_11, INV_13, INV_15 = (wp.constant(wp.float64(1.0 / n))
                                                      for n in (3, 5, 7, 9, 11, 13, 15))


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
def arctan2(y: wp.float64, x: wp.float64) -> wp.float64:
    """atan2(y, x); by its series where |y| <= x / 10 (error below 1e-17: no libm call)."""
    if x > F64_ZERO and wp.abs(y) <= wp.float64(0.1) * x:
        z = y / x
        z2 = z * z
        return z * (F64_ONE - z2 * (INV_3 - z2 * (INV_5 - z2 * (INV_7 - z2 * (INV_9 - z2 * (INV_11
            - z2 * (INV_13 - z2 * INV_15)))))))
    return wp.atan2(y, x)


@wp.func
def definite_integral(a0: wp.float64, b0: wp.float64, htt: wp.float64, htu: wp.float64,
                      det: wp.float64, s_lo: wp.float64, s_hi: wp.float64) -> wp.float64:
    """Int (M g . u) / (g^T M g) ds for M = adj(H), H definite: the numerator is constant,
    (1 / sqrt(det)) [arctan((a0 + htt s) / c)] with c = (htt b0 - htu a0) / sqrt(det)."""
    sd = wp.sqrt(det)
    c = (htt * b0 - htu * a0) / sd
    x1 = a0 + htt * s_lo
    x2 = a0 + htt * s_hi
    return arctan2(c * (x2 - x1), c * c + x1 * x2) / sd


@wp.func
def general_integral(a0: wp.float64, b0: wp.float64, htt: wp.float64, htu: wp.float64,
                     m00: wp.float64, m01: wp.float64, m11: wp.float64, s_lo: wp.float64,
                     s_hi: wp.float64) -> wp.float64:
    """The same integral for any positive definite M: numerator c(s) = (M g)_u linear,
    denominator q(s) = g^T M g quadratic (a log and an arctangent)."""
    g0 = wp.vec2d(a0, b0)
    g1 = wp.vec2d(htt, htu)
    mg1 = wp.vec2d(m00 * g1[0] + m01 * g1[1], m01 * g1[0] + m11 * g1[1])
    q2 = wp.dot(g1, mg1)
    q1 = F64_TWO * wp.dot(g0, mg1)
    det_m = m00 * m11 - m01 * m01
    sd = wp.sqrt(det_m)
    gamma = g1[0] * g0[1] - g1[1] * g0[0]
    jmg1 = wp.vec2d(-mg1[1], mg1[0])
    mjmg1_u = m01 * jmg1[0] + m11 * jmg1[1]
    y1 = F64_TWO * q2 * s_lo + q1
    y2 = F64_TWO * q2 * s_hi + q1
    arc = arctan2(F64_TWO * sd * gamma * (y2 - y1), wp.float64(4.0) * det_m * gamma * gamma + y1 * y2)
    ga = g0 + s_lo * g1
    gb = g0 + s_hi * g1
    qa = ga[0] * (m00 * ga[0] + m01 * ga[1]) + ga[1] * (m01 * ga[0] + m11 * ga[1])
    qb = gb[0] * (m00 * gb[0] + m01 * gb[1]) + gb[1] * (m01 * gb[0] + m11 * gb[1])
    log_term = mg1[1] / (F64_TWO * q2) * wp.log(wp.max(qb, TINY) / wp.max(qa, TINY))
    return log_term + mjmg1_u / (q2 * sd) * arc


@wp.func
def path_metric(htt: wp.float64, htu: wp.float64, huu: wp.float64):
    """K: H itself where it is definite and better conditioned than 1 / BETA, else |H| with its
    small eigenvalue raised to BETA times the large one (positive definite, continuous in H;
    |H| = (H^2 + |det H| I) / (|l1| + |l2|) needs no eigenvectors). Returns (definite, det H,
    K00, K01, K11)."""
    det = htt * huu - htu * htu
    tr = htt + huu
    if det >= RHO_2 * tr * tr:
        return True, det, htt, htu, huu
    dd2 = wp.sqrt((htt - huu) * (htt - huu) + wp.float64(4.0) * htu * htu)  # l1 - l2
    big = wp.max(wp.max(wp.abs(tr), dd2), TINY)  # |l1| + |l2|
    small = wp.min(wp.abs(tr), dd2)  # | |l1| - |l2| |
    a_det = wp.abs(det)
    mu = wp.max(F64_ZERO, BETA * F64_HALF * (big + small) - F64_HALF * (big - small))
    return (False, det, (htt * htt + htu * htu + a_det) / big + mu, htu * tr / big,
            (huu * huu + htu * htu + a_det) / big + mu)


@wp.func
def endpoint_integral(a0: wp.float64, b0: wp.float64, htt: wp.float64, htu: wp.float64,
                      definite: bool, det: wp.float64, k00: wp.float64, k01: wp.float64,
                      k11: wp.float64, s_lo: wp.float64, s_hi: wp.float64) -> wp.float64:
    """The element's end-point weight: Int (M g . u) / (g^T M g) ds over s_lo..s_hi, g = (a0 +
    htt s, b0 + htu s), M = adj(K) (:func:`path_metric`); in m: the Gauss weight times the
    integrand, or near a zero of g the exact integral of this linear model.

    With K = H (definite) the exact case: the jump at a reflection boundary is 2 pi /
    sqrt(det H). Rule: r = h |g1| / |g0| (h the share's length); the Gauss point value h c0 /
    q0 while r < NEAR_1 (the integrand is smooth there and the edge's Gauss rule keeps its
    order), the closed form beyond NEAR_2, a smooth blend of the two between.
    """
    m00 = k11
    m01 = -k01
    m11 = k00
    h = s_hi - s_lo
    g0_2 = a0 * a0 + b0 * b0
    r2 = h * h * (htt * htt + htu * htu)
    c0 = m01 * a0 + m11 * b0
    q0 = a0 * (m00 * a0 + m01 * b0) + b0 * (m01 * a0 + m11 * b0)
    point = F64_ZERO
    if r2 < NEAR_2 * NEAR_2 * g0_2:
        point = h * c0 / q0
        if r2 <= NEAR_1 * NEAR_1 * g0_2:
            return point
    exact = F64_ZERO
    if definite:
        exact = definite_integral(a0, b0, htt, htu, det, s_lo, s_hi)
    else:
        exact = general_integral(a0, b0, htt, htu, m00, m01, m11, s_lo, s_hi)
    if r2 >= NEAR_2 * NEAR_2 * g0_2:
        return exact
    x = (wp.sqrt(r2 / g0_2) - NEAR_1) / (NEAR_2 - NEAR_1)
    chi = x * x * (wp.float64(3.0) - F64_TWO * x)
    return point + chi * (exact - point)


@wp.func
def diffraction_pair(p: wp.vec3d, e: Diffraction, k: wp.float64, k_inv: wp.float64,
                     table: wp.array(dtype=wp.vec2d)) -> vec6d:
    """E (V/m) at P of the edge element's full diffraction: the fringe currents of
    :mod:`raysim.optics.kernels.ptd` and PO's end-point current, through one Green's function."""
    f = e.edge
    d = p - f.r
    R2 = wp.dot(d, d)
    inv = F64_ONE / wp.sqrt(R2)
    r_hat = d * inv
    current, moment = fringe_currents(d, inv, f)
    g = e.k_i - r_hat
    a0 = wp.dot(g, f.t)
    b0 = wp.dot(g, f.x)
    rt = wp.dot(r_hat, f.t)
    ru = wp.dot(r_hat, f.x)
    gn = wp.dot(g, f.y)
    htt = (F64_ONE - rt * rt) * inv + gn * e.kappa[0]
    htu = -rt * ru * inv + gn * e.kappa[1]
    huu = (F64_ONE - ru * ru) * inv + gn * e.kappa[2]
    definite, det, k00, k01, k11 = path_metric(htt, htu, huu)
    w = endpoint_integral(a0, b0, htt, htu, definite, det, k00, k01, k11, e.s_lo, e.s_hi)
    u = inv * k_inv
    bracket = electric_bracket(d, inv, u, current[0] * f.t + w * e.j_re, current[1] * f.t + w * e.j_im) \
        + magnetic_bracket(d, inv, u, moment[0] * f.t, moment[1] * f.t)
    return times(bracket, green(k, R2, inv, table))


radiate_diffraction, radiate_diffraction4 = radiation_kernels(load_diffraction, diffraction_pair)
