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
Green's function (the same near-field terms as :mod:`raysim.optics.kernels.po`). Floors keep
every value finite: sin^2(beta) >= SIN2_MIN (observation along the edge line, where a line
current radiates nothing), s >= S_MIN (the grazing direction s_g, where the bracket vanishes
with s) and s + c >= G_MIN (Ufimtsev's singularity: grazing incidence observed straight on).
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.po import cis

wp.set_module_options({"enable_backward": False})

vec6d = wp.types.vector(length=6, dtype=wp.float64)

ROWS = 23  # r (3), t (3), x (3), y (3), sin b', cos b', c, CE, CH, CB, CM (2 each)
F64_ZERO = wp.constant(wp.float64(0.0))
F64_HALF = wp.constant(wp.float64(0.5))
F64_ONE = wp.constant(wp.float64(1.0))
F64_THREE = wp.constant(wp.float64(3.0))
SIN2_MIN = wp.constant(wp.float64(1.0e-12))
S_MIN = wp.constant(wp.float64(1.0e-9))
G_MIN = wp.constant(wp.float64(1.0e-3))


@wp.func
def fringe_pair(px: wp.float64, py: wp.float64, pz: wp.float64, src: wp.array2d(dtype=wp.float64),
                e: int, k: wp.float64, k_inv: wp.float64, table: wp.array(dtype=wp.vec2d)) -> vec6d:
    """E (V/m) at P of edge element e's fringe currents, as (Re x, y, z, Im x, y, z)."""
    dx = px - src[0, e]
    dy = py - src[1, e]
    dz = pz - src[2, e]
    R2 = dx * dx + dy * dy + dz * dz
    inv = F64_ONE / wp.sqrt(R2)
    ux = dx * inv  # s_hat
    uy = dy * inv
    uz = dz * inv
    tx = src[3, e]
    ty = src[4, e]
    tz = src[5, e]
    st = ux * tx + uy * ty + uz * tz
    sx = ux * src[6, e] + uy * src[7, e] + uz * src[8, e]
    sy = ux * src[9, e] + uy * src[10, e] + uz * src[11, e]
    sin_b = src[12, e]
    cos_b = src[13, e]
    c = src[14, e]
    sin2 = wp.max(F64_ONE - st * st, SIN2_MIN)
    # 1 - mu = (1 - s_hat . s_g) / sin^2(beta'); s = sin(alpha / 2)
    one_minus_mu = wp.max(F64_ONE - (sin_b * sx + cos_b * st), F64_ZERO) / (sin_b * sin_b)
    s = wp.max(wp.sqrt(F64_HALF * one_minus_mu), S_MIN)
    g = wp.max(s + c, G_MIN)
    q = F64_ONE / (s * g)
    f_i = q * ((cos_b / sin_b) * (F64_ONE - one_minus_mu) - sx * st / sin2)
    f_m = q * sy / sin2
    inv_g = F64_ONE / g
    i_r = src[15, e] * inv_g + src[17, e] + src[19, e] * f_i
    i_i = src[16, e] * inv_g + src[18, e] + src[20, e] * f_i
    m_r = src[21, e] * f_m
    m_i = src[22, e] * f_m
    # near-field dyadic terms: a = 1 - j u - u^2, b = 1 - 3 j u - 3 u^2 (electric), 1 - j u
    # (magnetic), u = 1 / (kR)
    u = inv * k_inv
    u2 = u * u
    a_r = F64_ONE - u2
    b_r = F64_ONE - F64_THREE * u2
    b_u = F64_THREE * u
    ai_r = a_r * i_r + u * i_i
    ai_i = a_r * i_i - u * i_r
    bi_r = (b_r * i_r + b_u * i_i) * st
    bi_i = (b_r * i_i - b_u * i_r) * st
    mm_r = m_r + u * m_i
    mm_i = m_i - u * m_r
    cx = uy * tz - uz * ty  # s_hat x t
    cy = uz * tx - ux * tz
    cz = ux * ty - uy * tx
    vrx = ai_r * tx - bi_r * ux + mm_r * cx
    vry = ai_r * ty - bi_r * uy + mm_r * cy
    vrz = ai_r * tz - bi_r * uz + mm_r * cz
    vix = ai_i * tx - bi_i * ux + mm_i * cx
    viy = ai_i * ty - bi_i * uy + mm_i * cy
    viz = ai_i * tz - bi_i * uz + mm_i * cz
    ph = cis(k * R2 * inv, table)
    gr = ph[0] * inv  # exp(-jkR) / R = gr + j gi
    gi = -ph[1] * inv
    return vec6d(gr * vrx - gi * vix, gr * vry - gi * viy, gr * vrz - gi * viz,
                 gr * vix + gi * vrx, gr * viy + gi * vry, gr * viz + gi * vrz)


@wp.kernel
def radiate_fringe(
    field: wp.array2d(dtype=wp.float64),
    src: wp.array2d(dtype=wp.float64),
    begin: int,
    end: int,
    k: wp.float64,
    k_inv: wp.float64,
    table: wp.array(dtype=wp.vec2d),
    E: wp.array2d(dtype=wp.float64),
    offset: int,
):
    """E[:, i] += sum over edge elements begin..end-1 of :func:`fringe_pair` at field[:, i]."""
    i = wp.tid() + offset
    px = field[0, i]
    py = field[1, i]
    pz = field[2, i]
    acc = vec6d()
    for e in range(begin, end):
        acc += fringe_pair(px, py, pz, src, e, k, k_inv, table)
    for c in range(6):
        E[c, i] = E[c, i] + acc[c]
