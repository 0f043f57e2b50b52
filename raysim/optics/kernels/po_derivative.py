"""Warp kernels of the PO engine's derivative with respect to the surface: JVP and VJP pairs.

Time convention exp(+j w t), SI units, reflector frame; the radiation of an electric moment p
at S seen from P (d = P - S, R = |d|, R_hat = d / R, u = 1 / (kR)) is, less the prefactor
-j k eta / (4 pi) that :class:`raysim.optics.radiator.Radiator` applies,

    G(d) p = g(R) [a p - b (R_hat . p) R_hat],   g = exp(-j k R) / R,
    a = 1 - j u - u^2,   b = 1 - 3 j u - 3 u^2

(:mod:`raysim.optics.kernels.radiation`). When the element moves, S -> S + eps v, the field of
a fixed moment m changes by eps D_w[G(d) m] with w = -v (d moves the other way). Worked out
from dg/dR = -k (j + u) g, da/dR = k u (j u + 2 u^2), db/dR = k u (3 j u + 6 u^2) and
dR_hat = (w - (R_hat . w) R_hat) / R, with c = R_hat . w, m_R = R_hat . m:

    D_w[G m] = g [alpha m + beta R_hat + gamma w],
    alpha = c k (-j - 2u + 3j u^2 + 3u^3),
    beta  = k [c m_R (j + 6u - 15j u^2 - 15u^3) - u b (w . m)],
    gamma = -k u b m_R,

which tends to -j k c G m far away (the phase of a moved source). Element layouts:

- ``shift`` elements (:data:`SHIFT_ROWS` = 18, the JVP): position r (3), moment m (Re 3, Im 3),
  moment change p (Re 3, Im 3), displacement v (3, real). The pair is G(d) p + D_{-v}[G m]:
  the first-order field change of an element whose moment changes by p as it moves by v.
- ``adjoint`` sources (:data:`ADJOINT_ROWS` = 12, the VJP): position r (3), moment m (6), the
  direction w = -v of a unit displacement (3); field points carry P (3) and a complex weight
  b (Re 3, Im 3). Per source the kernel sums U = sum_P G(d) b (G is symmetric, so b . G q =
  U . q for any moment q) and S = sum_P b . D_w[G m], written as (U Re 3, U Im 3, S Re, S Im)
  into a (8, n_sources) array: the transposed sum, field points as sources.
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.f64 import F64_ONE, F64_THREE, F64_TWO
from raysim.optics.kernels.po import Dipole, load_dipole
from raysim.optics.kernels.ptd import EdgeElement, fringe_pair, load_edge
from raysim.optics.kernels.radiation import (
    Offsets4,
    adjoint_kernel,
    electric_bracket,
    electric_bracket4,
    green,
    green4,
    lanes3,
    lanes6,
    lanes8,
    offsets4,
    radiation_kernels,
    segment_adjoint_kernel,
    segment_kernel,
    splat,
    splat3,
    times,
    times4,
    vec4d,
    vec6d,
    vec8d,
)

wp.set_module_options({"enable_backward": False})

SHIFT_ROWS = 18
ADJOINT_ROWS = 12
ADJOINT_OUT = 8
F64_SIX = wp.constant(wp.float64(6.0))
F64_NINE = wp.constant(wp.float64(9.0))
F64_FIFTEEN = wp.constant(wp.float64(15.0))


@wp.struct
class ShiftElement:
    """A moving current element: position r (m), moment m and its change p (A m), displacement v."""

    r: wp.vec3d
    mre: wp.vec3d
    mim: wp.vec3d
    pre: wp.vec3d
    pim: wp.vec3d
    v: wp.vec3d


@wp.func
def load_shift(src: wp.array2d(dtype=wp.float64), s: int) -> ShiftElement:
    e = ShiftElement()
    e.r = wp.vec3d(src[0, s], src[1, s], src[2, s])
    e.mre = wp.vec3d(src[3, s], src[4, s], src[5, s])
    e.mim = wp.vec3d(src[6, s], src[7, s], src[8, s])
    e.pre = wp.vec3d(src[9, s], src[10, s], src[11, s])
    e.pim = wp.vec3d(src[12, s], src[13, s], src[14, s])
    e.v = wp.vec3d(src[15, s], src[16, s], src[17, s])
    return e


@wp.func
def cmul(a: wp.vec2d, b: wp.vec2d) -> wp.vec2d:
    return wp.vec2d(a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0])


@wp.func
def moved(d: wp.vec3d, inv: wp.float64, u: wp.float64, k: wp.float64, mre: wp.vec3d,
          mim: wp.vec3d, w: wp.vec3d) -> vec6d:
    """alpha m + beta R_hat + gamma w (module docstring): D_w[G m] / g, without g."""
    rh = d * inv
    c = wp.dot(rh, w)
    mr = wp.vec2d(wp.dot(rh, mre), wp.dot(rh, mim))
    wm = wp.vec2d(wp.dot(w, mre), wp.dot(w, mim))
    u2 = u * u
    u3 = u2 * u
    b = wp.vec2d(F64_ONE - F64_THREE * u2, -F64_THREE * u)
    alpha = wp.vec2d(-F64_TWO * u + F64_THREE * u3, -F64_ONE + F64_THREE * u2) * (c * k)
    poly = wp.vec2d(F64_SIX * u - F64_FIFTEEN * u3, F64_ONE - F64_FIFTEEN * u2)
    beta = (cmul(poly, mr) * c - cmul(b, wm) * u) * k
    gamma = cmul(b, mr) * (-k * u)
    vr = alpha[0] * mre - alpha[1] * mim + beta[0] * rh + gamma[0] * w
    vi = alpha[0] * mim + alpha[1] * mre + beta[1] * rh + gamma[1] * w
    return vec6d(vr[0], vr[1], vr[2], vi[0], vi[1], vi[2])


@wp.func
def shift_pair(p: wp.vec3d, e: ShiftElement, k: wp.float64, k_inv: wp.float64,
               table: wp.array(dtype=wp.vec2d)) -> vec6d:
    """g [a p - b (R_hat . p) R_hat] + D_{-v}[G m] at P: the JVP of one moving element."""
    d = p - e.r
    R2 = wp.dot(d, d)
    inv = F64_ONE / wp.sqrt(R2)
    u = inv * k_inv
    bracket = electric_bracket(d, inv, u, e.pre, e.pim) + moved(d, inv, u, k, e.mre, e.mim, -e.v)
    return times(bracket, green(k, R2, inv, table))


@wp.func
def moved4(d: Offsets4, k: wp.float64, mre: wp.vec3d, mim: wp.vec3d, w: wp.vec3d) -> lanes6:
    """:func:`moved` at four points in vector lanes (the element's m and w the same in all)."""
    rx = wp.cw_mul(d.x, d.inv)
    ry = wp.cw_mul(d.y, d.inv)
    rz = wp.cw_mul(d.z, d.inv)
    c = rx * w[0] + ry * w[1] + rz * w[2]
    mr_r = rx * mre[0] + ry * mre[1] + rz * mre[2]
    mr_i = rx * mim[0] + ry * mim[1] + rz * mim[2]
    wm_r = wp.dot(w, mre)
    wm_i = wp.dot(w, mim)
    u = d.u
    u2 = wp.cw_mul(u, u)
    u3 = wp.cw_mul(u2, u)
    b_r = splat(F64_ONE) - u2 * F64_THREE
    b_i = -(u * F64_THREE)
    ck = c * k
    alpha_r = wp.cw_mul(u3 * F64_THREE - u * F64_TWO, ck)
    alpha_i = wp.cw_mul(u2 * F64_THREE - splat(F64_ONE), ck)
    poly_r = u * F64_SIX - u3 * F64_FIFTEEN
    poly_i = splat(F64_ONE) - u2 * F64_FIFTEEN
    beta_r = (wp.cw_mul(wp.cw_mul(poly_r, mr_r) - wp.cw_mul(poly_i, mr_i), c)
              - wp.cw_mul(b_r * wm_r - b_i * wm_i, u)) * k
    beta_i = (wp.cw_mul(wp.cw_mul(poly_r, mr_i) + wp.cw_mul(poly_i, mr_r), c)
              - wp.cw_mul(b_r * wm_i + b_i * wm_r, u)) * k
    gamma_r = wp.cw_mul(wp.cw_mul(b_r, mr_r) - wp.cw_mul(b_i, mr_i), u) * (-k)
    gamma_i = wp.cw_mul(wp.cw_mul(b_r, mr_i) + wp.cw_mul(b_i, mr_r), u) * (-k)
    return wp.matrix_from_rows(
        alpha_r * mre[0] - alpha_i * mim[0] + wp.cw_mul(beta_r, rx) + gamma_r * w[0],
        alpha_r * mre[1] - alpha_i * mim[1] + wp.cw_mul(beta_r, ry) + gamma_r * w[1],
        alpha_r * mre[2] - alpha_i * mim[2] + wp.cw_mul(beta_r, rz) + gamma_r * w[2],
        alpha_r * mim[0] + alpha_i * mre[0] + wp.cw_mul(beta_i, rx) + gamma_i * w[0],
        alpha_r * mim[1] + alpha_i * mre[1] + wp.cw_mul(beta_i, ry) + gamma_i * w[1],
        alpha_r * mim[2] + alpha_i * mre[2] + wp.cw_mul(beta_i, rz) + gamma_i * w[2])


@wp.func
def shift_pair4(px: vec4d, py: vec4d, pz: vec4d, e: ShiftElement, k: wp.float64, k_inv: wp.float64,
                table: wp.array(dtype=wp.vec2d)) -> lanes6:
    """:func:`shift_pair` at four points in vector lanes."""
    d = offsets4(px, py, pz, e.r, k_inv)
    bracket = electric_bracket4(d, splat3(e.pre), splat3(e.pim)) + moved4(d, k, e.mre, e.mim, -e.v)
    return times4(bracket, green4(k, d.R2, d.inv, table))


radiate_shift, radiate_shift4 = radiation_kernels(load_shift, shift_pair, shift_pair4)
segments_shift = segment_kernel(load_shift, shift_pair, shift_pair4)


@wp.struct
class AdjointSource:
    """A PO element seen by the adjoint: the dipole and the direction w of its displacement."""

    dipole: Dipole
    w: wp.vec3d


@wp.func
def load_adjoint(src: wp.array2d(dtype=wp.float64), s: int) -> AdjointSource:
    e = AdjointSource()
    e.dipole = load_dipole(src, s)
    e.w = wp.vec3d(src[9, s], src[10, s], src[11, s])
    return e


@wp.func
def adjoint_pair(P: wp.vec3d, bre: wp.vec3d, bim: wp.vec3d, a: AdjointSource, k: wp.float64,
                 k_inv: wp.float64, table: wp.array(dtype=wp.vec2d)) -> vec8d:
    """(G(d) b, b . D_w[G m]) of one field point P with weight b for the source (moment m,
    displacement direction w): the terms of U and S (module docstring)."""
    e = a.dipole
    d = P - e.r
    R2 = wp.dot(d, d)
    inv = F64_ONE / wp.sqrt(R2)
    u = inv * k_inv
    g = green(k, R2, inv, table)
    U = times(electric_bracket(d, inv, u, bre, bim), g)
    D = times(moved(d, inv, u, k, e.re, e.im, a.w), g)
    dr = wp.vec3d(D[0], D[1], D[2])
    di = wp.vec3d(D[3], D[4], D[5])
    return vec8d(U[0], U[1], U[2], U[3], U[4], U[5],
                 wp.dot(bre, dr) - wp.dot(bim, di), wp.dot(bre, di) + wp.dot(bim, dr))


@wp.func
def adjoint_pair4(px: vec4d, py: vec4d, pz: vec4d, bre: lanes3, bim: lanes3, a: AdjointSource,
                  k: wp.float64, k_inv: wp.float64, table: wp.array(dtype=wp.vec2d)) -> lanes8:
    """:func:`adjoint_pair` at four points in vector lanes, each with its own weight b."""
    e = a.dipole
    d = offsets4(px, py, pz, e.r, k_inv)
    g = green4(k, d.R2, d.inv, table)
    U = times4(electric_bracket4(d, bre, bim), g)
    D = times4(moved4(d, k, e.re, e.im, a.w), g)
    s_r = (wp.cw_mul(bre[0], D[0]) + wp.cw_mul(bre[1], D[1]) + wp.cw_mul(bre[2], D[2])) \
        - (wp.cw_mul(bim[0], D[3]) + wp.cw_mul(bim[1], D[4]) + wp.cw_mul(bim[2], D[5]))
    s_i = (wp.cw_mul(bre[0], D[3]) + wp.cw_mul(bre[1], D[4]) + wp.cw_mul(bre[2], D[5])) \
        + (wp.cw_mul(bim[0], D[0]) + wp.cw_mul(bim[1], D[1]) + wp.cw_mul(bim[2], D[2]))
    return wp.matrix_from_rows(U[0], U[1], U[2], U[3], U[4], U[5], s_r, s_i)


@wp.func
def fringe_adjoint_pair(P: wp.vec3d, bre: wp.vec3d, bim: wp.vec3d, e: EdgeElement,
                        k: wp.float64, k_inv: wp.float64,
                        table: wp.array(dtype=wp.vec2d)) -> vec8d:
    """Re(b . E) of one fringe element's field at P, in the first slot."""
    v = fringe_pair(P, e, k, k_inv, table)
    out = vec8d()
    out[0] = (wp.dot(bre, wp.vec3d(v[0], v[1], v[2]))
              - wp.dot(bim, wp.vec3d(v[3], v[4], v[5])))
    return out


adjoint_sum = adjoint_kernel(load_adjoint, adjoint_pair, adjoint_pair4)
fringe_adjoint = adjoint_kernel(load_edge, fringe_adjoint_pair)
# the same pairs summed over each leaf's chart grid: the fast radiator's transposed sum
segments_adjoint = segment_adjoint_kernel(load_adjoint, adjoint_pair, adjoint_pair4)
segments_fringe_adjoint = segment_adjoint_kernel(load_edge, fringe_adjoint_pair)
