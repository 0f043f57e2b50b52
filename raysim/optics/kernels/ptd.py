"""Warp kernels of the edge-diffraction engine (see :mod:`raysim.optics.ptd`): fringe currents radiated.

Time convention exp(+j w t), SI units, reflector frame. Each edge element is one Gauss point
of an edge, stored column-wise in a ``(ROWS, N)`` float64 array (see :data:`ROWS`): its
position r (m); the right-handed edge frame of the local half-plane, t (edge tangent), x (in
the plate, normal to the edge, pointing into it) and y (the plate's normal on the lit side);
sin(beta') and cos(beta') of the incidence (cos(beta') = k_hat_i . t); c = cos(phi' / 2),
phi' in (0, pi) the incidence angle measured from the plate in the (x, y) plane; and four
complex coefficients CE, CH, CB, CM that hold the incident field's edge components (E_t and
H_t, with phase), the element length dl and the radiation prefactors -j k eta / (4 pi)
(electric) and j k / (4 pi) (magnetic), so the kernel sums fields in V/m directly.

Michaeli's fringe equivalent edge currents of a half-plane (exterior wedge angle 2 pi), in the
form derived in :mod:`raysim.optics.ptd`: for the direction s_hat = (P - r) / |P - r|,

    s = sin(alpha / 2) = sqrt((1 - s_hat . s_g) / 2) / sin(beta'),
    s_g = sin(beta') x + cos(beta') t          (the grazing diffracted ray on the plate),
    mu = cos(alpha) = 1 - 2 s^2,
    q = 1 / (s (s + c)),
    I dl = CE / (s + c) + CH + CB q [cot(beta') mu - (s_hat . x)(s_hat . t) / sin^2(beta)],
    M dl = CM q (s_hat . y) / sin^2(beta),          sin^2(beta) = 1 - (s_hat . t)^2,

radiated as I dl t (electric) and M dl t (magnetic) through the full free-space dyadic
Green's function (the brackets of :mod:`raysim.optics.kernels.radiation`). Floors keep
every value finite: sin^2(beta) >= SIN2_MIN (observation along the edge line, where a line
current radiates nothing), s >= S_MIN (the grazing direction s_g, where the bracket vanishes
with s) and s + c >= G_MIN (Ufimtsev's singularity: grazing incidence observed straight on).
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.f64 import F64_HALF, F64_ONE, F64_ZERO
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

ROWS = 23  # r (3), t (3), x (3), y (3), sin b', cos b', c, CE, CH, CB, CM (2 each)
SIN2_MIN = wp.constant(wp.float64(1.0e-12))
S_MIN = wp.constant(wp.float64(1.0e-9))
G_MIN = wp.constant(wp.float64(1.0e-3))


@wp.struct
class EdgeElement:
    """One Gauss point of an edge: position r (m), edge frame t, x, y, incidence and the
    complex coefficients CE, CH, CB, CM (see the module docstring)."""

    r: wp.vec3d
    t: wp.vec3d
    x: wp.vec3d
    y: wp.vec3d
    sin_b: wp.float64
    cos_b: wp.float64
    c: wp.float64
    CE: wp.vec2d
    CH: wp.vec2d
    CB: wp.vec2d
    CM: wp.vec2d


@wp.func
def load_edge(src: wp.array2d(dtype=wp.float64), s: int) -> EdgeElement:
    e = EdgeElement()
    e.r = wp.vec3d(src[0, s], src[1, s], src[2, s])
    e.t = wp.vec3d(src[3, s], src[4, s], src[5, s])
    e.x = wp.vec3d(src[6, s], src[7, s], src[8, s])
    e.y = wp.vec3d(src[9, s], src[10, s], src[11, s])
    e.sin_b = src[12, s]
    e.cos_b = src[13, s]
    e.c = src[14, s]
    e.CE = wp.vec2d(src[15, s], src[16, s])
    e.CH = wp.vec2d(src[17, s], src[18, s])
    e.CB = wp.vec2d(src[19, s], src[20, s])
    e.CM = wp.vec2d(src[21, s], src[22, s])
    return e


@wp.func
def fringe_currents(d: wp.vec3d, inv: wp.float64, e: EdgeElement):
    """I dl and M dl (complex, as (Re, Im)) of the edge element e seen along d = P - r
    (1 / |d| = inv): the module docstring's currents, both along e.t."""
    s_hat = d * inv
    st = wp.dot(s_hat, e.t)
    sx = wp.dot(s_hat, e.x)
    sy = wp.dot(s_hat, e.y)
    sin2 = wp.max(F64_ONE - st * st, SIN2_MIN)
    # 1 - mu = (1 - s_hat . s_g) / sin^2(beta'); s = sin(alpha / 2)
    one_minus_mu = wp.max(F64_ONE - (e.sin_b * sx + e.cos_b * st), F64_ZERO) / (e.sin_b * e.sin_b)
    s = wp.max(wp.sqrt(F64_HALF * one_minus_mu), S_MIN)
    g = wp.max(s + e.c, G_MIN)
    q = F64_ONE / (s * g)
    f_i = q * ((e.cos_b / e.sin_b) * (F64_ONE - one_minus_mu) - sx * st / sin2)
    f_m = q * sy / sin2
    current = e.CE * (F64_ONE / g) + e.CH + e.CB * f_i  # I dl (complex)
    moment = e.CM * f_m  # M dl (complex)
    return current, moment


@wp.func
def fringe_pair(p: wp.vec3d, e: EdgeElement, k: wp.float64, k_inv: wp.float64,
                table: wp.array(dtype=wp.vec2d)) -> vec6d:
    """E (V/m) at P of the edge element e's fringe currents, as (Re x, y, z, Im x, y, z)."""
    d = p - e.r
    R2 = wp.dot(d, d)
    inv = F64_ONE / wp.sqrt(R2)
    current, moment = fringe_currents(d, inv, e)
    u = inv * k_inv
    bracket = electric_bracket(d, inv, u, current[0] * e.t, current[1] * e.t) \
        + magnetic_bracket(d, inv, u, moment[0] * e.t, moment[1] * e.t)
    return times(bracket, green(k, R2, inv, table))


radiate_fringe, radiate_fringe4 = radiation_kernels(load_edge, fringe_pair)
segments_fringe = segment_kernel(load_edge, fringe_pair)
