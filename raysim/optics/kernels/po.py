"""Warp kernels of the physical-optics engine (see :mod:`raysim.optics.po`): currents and radiation.

Time convention exp(+j w t), SI units, reflector frame. Complex vectors travel as separate real
and imaginary parts. Current elements are stored column-wise in a ``(9, N)`` float64 array:
rows 0-2 the position (m), rows 3-5 and 6-8 the real and imaginary parts of the element's
moment (J dA in A m for electric elements, M dA in V m for magnetic ones). Fields accumulate in
a ``(6, n)`` array (real x, y, z, then imaginary x, y, z) without the constant prefactor, which
:mod:`raysim.optics.po` applies once:

- electric element p (A m) at distance R (Balanis, *Advanced Engineering Electromagnetics*,
  2nd ed., ch. 6, the potentials of a current element, with the dyadic Green's function):
  E = -j k eta / (4 pi) * exp(-j k R) / R * [a p - b (R_hat . p) R_hat],
  a = 1 - j/(kR) - 1/(kR)^2, b = 1 - 3j/(kR) - 3/(kR)^2;
  the kernels sum exp(-j k R) / R * [a p - b (R_hat . p) R_hat].
- magnetic element m (V m): E = j k / (4 pi) * exp(-j k R) / R * (1 - j/(kR)) R_hat x m;
  the kernels sum exp(-j k R) / R * (1 - j/(kR)) R_hat x m.

exp(-j k R) comes from :func:`cis`: Cody-Waite reduction of kR by 2 pi / 256 (a three-part
constant, exact products), a 256-entry table of cos and sin, and Taylor polynomials on the
remainder |r| <= pi / 256 (error below 1e-17); about 2e-16 in all, with no libm call.
Every kernel takes a trailing ``offset: int`` and indexes ``wp.tid() + offset`` so that
:func:`raysim.optics.runtime.launch` can split it across CPU threads.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})

vec6d = wp.types.vector(length=6, dtype=wp.float64)

# pi to 60 digits; the reduction constant 2 pi / TABLE_SIZE is split in two 26-bit heads (so
# that n * head is exact for n < 2^27, kR < 2^27 * 2 pi / 256 = 3.3e6 rad) and a rounded tail
_PI = Fraction("3.14159265358979323846264338327950288419716939937510582097494")
TABLE_SIZE = 256
_step = 2 * _PI / TABLE_SIZE


def _head(x: Fraction, bits: int) -> float:
    m, e = math.frexp(float(x))
    return math.ldexp(math.floor(m * 2**bits) / 2**bits, e)


_h1 = _head(_step, 26)
_h2 = _head(_step - Fraction(_h1), 26)
STEP_1 = wp.constant(wp.float64(_h1))
STEP_2 = wp.constant(wp.float64(_h2))
STEP_3 = wp.constant(wp.float64(float(_step - Fraction(_h1) - Fraction(_h2))))
INV_STEP = wp.constant(wp.float64(float(1 / _step)))
TABLE_MASK = wp.constant(TABLE_SIZE - 1)
MAX_PHASE = float(2**27 * _step)  # rad: beyond it the reduction loses exactness

F64_ZERO = wp.constant(wp.float64(0.0))
F64_HALF = wp.constant(wp.float64(0.5))
F64_ONE = wp.constant(wp.float64(1.0))
F64_TWO = wp.constant(wp.float64(2.0))
F64_THREE = wp.constant(wp.float64(3.0))
INV_6 = wp.constant(wp.float64(1.0 / 6.0))
INV_120 = wp.constant(wp.float64(1.0 / 120.0))
INV_24 = wp.constant(wp.float64(1.0 / 24.0))
INV_720 = wp.constant(wp.float64(1.0 / 720.0))


def cis_table() -> np.ndarray:
    """(TABLE_SIZE, 2) cos and sin of 2 pi j / TABLE_SIZE, for :func:`cis`."""
    t = 2.0 * np.pi * np.arange(TABLE_SIZE) / TABLE_SIZE
    return np.column_stack([np.cos(t), np.sin(t)])


@wp.func
def cis(x: wp.float64, table: wp.array(dtype=wp.vec2d)) -> wp.vec2d:
    """(cos x, sin x) for 0 <= x < MAX_PHASE, to about 2e-16."""
    n = wp.floor(x * INV_STEP + F64_HALF)
    r = ((x - n * STEP_1) - n * STEP_2) - n * STEP_3
    r2 = r * r
    s = r - r * r2 * (INV_6 - r2 * INV_120)
    c = F64_ONE - r2 * (F64_HALF - r2 * (INV_24 - r2 * INV_720))
    t = table[int(n) & TABLE_MASK]
    return wp.vec2d(t[0] * c - t[1] * s, t[1] * c + t[0] * s)


@wp.func
def electric_pair(px: wp.float64, py: wp.float64, pz: wp.float64, sx: wp.float64, sy: wp.float64,
                  sz: wp.float64, jrx: wp.float64, jry: wp.float64, jrz: wp.float64, jix: wp.float64,
                  jiy: wp.float64, jiz: wp.float64, k: wp.float64, k_inv: wp.float64,
                  table: wp.array(dtype=wp.vec2d)) -> vec6d:
    """exp(-jkR)/R [a p - b (R_hat . p) R_hat] at P of the electric element p at S (see the
    module docstring); returned as (Re x, y, z, Im x, y, z)."""
    dx = px - sx
    dy = py - sy
    dz = pz - sz
    R2 = dx * dx + dy * dy + dz * dz
    inv = F64_ONE / wp.sqrt(R2)
    u = inv * k_inv  # 1/(kR)
    u2 = u * u
    e = cis(k * R2 * inv, table)
    c = e[0] * inv  # exp(-jkR)/R = c + j sn
    sn = -e[1] * inv
    inv2 = inv * inv
    dr = (dx * jrx + dy * jry + dz * jrz) * inv2  # (R_hat . p) / R, real and imaginary
    di = (dx * jix + dy * jiy + dz * jiz) * inv2
    a_r = F64_ONE - u2  # a = a_r - j u
    b_r = F64_ONE - F64_THREE * u2  # b = b_r + j b_i
    b_i = -F64_THREE * u
    tr = b_r * dr - b_i * di
    ti = b_r * di + b_i * dr
    vrx = a_r * jrx + u * jix - tr * dx
    vry = a_r * jry + u * jiy - tr * dy
    vrz = a_r * jrz + u * jiz - tr * dz
    vix = a_r * jix - u * jrx - ti * dx
    viy = a_r * jiy - u * jry - ti * dy
    viz = a_r * jiz - u * jrz - ti * dz
    return vec6d(c * vrx - sn * vix, c * vry - sn * viy, c * vrz - sn * viz,
                 c * vix + sn * vrx, c * viy + sn * vry, c * viz + sn * vrz)


@wp.func
def magnetic_pair(px: wp.float64, py: wp.float64, pz: wp.float64, sx: wp.float64, sy: wp.float64,
                  sz: wp.float64, mrx: wp.float64, mry: wp.float64, mrz: wp.float64, mix: wp.float64,
                  miy: wp.float64, miz: wp.float64, k: wp.float64, k_inv: wp.float64,
                  table: wp.array(dtype=wp.vec2d)) -> vec6d:
    """exp(-jkR)/R (1 - j/(kR)) R_hat x m at P of the magnetic element m at S."""
    dx = px - sx
    dy = py - sy
    dz = pz - sz
    R2 = dx * dx + dy * dy + dz * dz
    inv = F64_ONE / wp.sqrt(R2)
    u = inv * k_inv
    e = cis(k * R2 * inv, table)
    g = inv * inv  # 1/R for exp(-jkR)/R and 1/R for R_hat
    # exp(-jkR) (1 - j u) = (cos + u (-sin)) + j(-sin - u cos)
    wr = (e[0] - u * e[1]) * g
    wi = (-e[1] - u * e[0]) * g
    crx = dy * mrz - dz * mry
    cry = dz * mrx - dx * mrz
    crz = dx * mry - dy * mrx
    cix = dy * miz - dz * miy
    ciy = dz * mix - dx * miz
    ciz = dx * miy - dy * mix
    return vec6d(wr * crx - wi * cix, wr * cry - wi * ciy, wr * crz - wi * ciz,
                 wr * cix + wi * crx, wr * ciy + wi * cry, wr * ciz + wi * crz)


@wp.kernel
def radiate_electric(
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
    """E[:, i] += sum over elements begin..end-1 of :func:`electric_pair` at field[:, i]."""
    i = wp.tid() + offset
    px = field[0, i]
    py = field[1, i]
    pz = field[2, i]
    acc = vec6d()
    for s in range(begin, end):
        acc += electric_pair(px, py, pz, src[0, s], src[1, s], src[2, s], src[3, s], src[4, s],
                             src[5, s], src[6, s], src[7, s], src[8, s], k, k_inv, table)
    for c in range(6):
        E[c, i] = E[c, i] + acc[c]


@wp.kernel
def radiate_electric4(
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
    """As :func:`radiate_electric` for the four field points 4t..4t+3 (t the thread): each
    element is loaded once for four points (the CPU's cache and registers do the rest)."""
    t = (wp.tid() + offset) * 4
    p0x = field[0, t]
    p0y = field[1, t]
    p0z = field[2, t]
    p1x = field[0, t + 1]
    p1y = field[1, t + 1]
    p1z = field[2, t + 1]
    p2x = field[0, t + 2]
    p2y = field[1, t + 2]
    p2z = field[2, t + 2]
    p3x = field[0, t + 3]
    p3y = field[1, t + 3]
    p3z = field[2, t + 3]
    a0 = vec6d()
    a1 = vec6d()
    a2 = vec6d()
    a3 = vec6d()
    for s in range(begin, end):
        sx = src[0, s]
        sy = src[1, s]
        sz = src[2, s]
        jrx = src[3, s]
        jry = src[4, s]
        jrz = src[5, s]
        jix = src[6, s]
        jiy = src[7, s]
        jiz = src[8, s]
        a0 += electric_pair(p0x, p0y, p0z, sx, sy, sz, jrx, jry, jrz, jix, jiy, jiz, k, k_inv, table)
        a1 += electric_pair(p1x, p1y, p1z, sx, sy, sz, jrx, jry, jrz, jix, jiy, jiz, k, k_inv, table)
        a2 += electric_pair(p2x, p2y, p2z, sx, sy, sz, jrx, jry, jrz, jix, jiy, jiz, k, k_inv, table)
        a3 += electric_pair(p3x, p3y, p3z, sx, sy, sz, jrx, jry, jrz, jix, jiy, jiz, k, k_inv, table)
    for c in range(6):
        E[c, t] = E[c, t] + a0[c]
        E[c, t + 1] = E[c, t + 1] + a1[c]
        E[c, t + 2] = E[c, t + 2] + a2[c]
        E[c, t + 3] = E[c, t + 3] + a3[c]


@wp.kernel
def radiate_magnetic(
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
    """E[:, i] += sum over elements begin..end-1 of :func:`magnetic_pair` at field[:, i]."""
    i = wp.tid() + offset
    px = field[0, i]
    py = field[1, i]
    pz = field[2, i]
    acc = vec6d()
    for s in range(begin, end):
        acc += magnetic_pair(px, py, pz, src[0, s], src[1, s], src[2, s], src[3, s], src[4, s],
                             src[5, s], src[6, s], src[7, s], src[8, s], k, k_inv, table)
    for c in range(6):
        E[c, i] = E[c, i] + acc[c]


@wp.kernel
def po_currents(
    points: wp.array(dtype=wp.vec3d),
    area: wp.array(dtype=wp.vec3d),
    k_hat: wp.vec3d,
    h_hat: wp.vec3d,
    k: wp.float64,
    eta: wp.float64,
    src: wp.array2d(dtype=wp.float64),
    offset: int,
):
    """PO current elements J dA = 2 n dA x H_inc at lit samples (A m), into ``src``.

    H_inc = h_hat / eta * exp(-j k k_hat . r) with h_hat = k_hat x e_hat (unit incident E);
    ``area`` is n dA with n already on the side the wave comes from (the caller turns it by
    the face's normal: a quadrature weight may be negative, so the sign of n dA . k_hat alone
    does not tell the lit side).
    """
    i = wp.tid() + offset
    r = points[i]
    v = wp.cross(area[i], h_hat) * (F64_TWO / eta)
    phase = k * wp.dot(k_hat, r)
    c = wp.cos(phase)
    s = -wp.sin(phase)
    src[0, i] = r[0]
    src[1, i] = r[1]
    src[2, i] = r[2]
    for j in range(3):
        src[3 + j, i] = v[j] * c
        src[6 + j, i] = v[j] * s


@wp.kernel
def lit_samples(
    mesh: wp.uint64,
    facet: wp.array(dtype=wp.vec3d),
    face: wp.array(dtype=wp.int32),
    k_hat: wp.vec3d,
    standoff: wp.float64,
    tolerance: wp.float64,
    lit: wp.array(dtype=wp.int32),
    offset: int,
):
    """lit[i] = 1 when the plane wave reaches the facet point facet[i] of face face[i].

    A ray starts ``standoff`` metres up-beam of the point (BVH in float32): the point is lit
    when the first face hit is its own, or lies within ``tolerance`` (m) of it (a neighbour
    sharing the edge). A miss is float32 round-off at an edge: lit.
    """
    i = wp.tid() + offset
    p = facet[i]
    origin = p - standoff * k_hat
    q = wp.mesh_query_ray(mesh, wp.vec3(origin), wp.normalize(wp.vec3(k_hat)), float(standoff * F64_TWO))
    lit[i] = 1
    if q.result:
        if q.face != face[i] and wp.float64(q.t) < standoff - tolerance:
            lit[i] = 0
