"""Warp kernels of the go+edge engine's edge waves (see :mod:`raysim.optics.goedge`; the
geometric wave's are in :mod:`raysim.optics.kernels.geowave`).

Time convention exp(+j w t), SI units, reflector frame; fields as (Re x, y, z, Im x, y, z).

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
from raysim.optics.kernels.ptd import ROWS as FRINGE_ROWS
from raysim.optics.kernels.ptd import EdgeElement, fringe_currents, load_edge
from raysim.optics.kernels.radiation import (
    electric_bracket,
    green,
    magnetic_bracket,
    radiation_kernels,
    segment_kernel,
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
segments_diffraction = segment_kernel(load_diffraction, diffraction_pair)
