"""The free-space radiation of point current elements, shared by every current-based engine.

Time convention exp(+j w t), SI units, reflector frame. Complex vectors travel as separate real
and imaginary parts; fields accumulate as ``vec6d`` (Re x, y, z, Im x, y, z). For an element at
S seen from the field point P, with d = P - S, R = |d|, R_hat = d / R and u = 1 / (kR):

- electric moment p (A m; J dA or I dl), Balanis, *Advanced Engineering Electromagnetics*,
  2nd ed., ch. 6 (the potentials of a current element, with the dyadic Green's function):
  E = -j k eta / (4 pi) * exp(-j k R) / R * [a p - b (R_hat . p) R_hat],
  a = 1 - j u - u^2, b = 1 - 3 j u - 3 u^2;
- magnetic moment m (V m; M dA or K dl), by duality:
  E = j k / (4 pi) * exp(-j k R) / R * (1 - j u) R_hat x m.

:func:`electric_bracket` and :func:`magnetic_bracket` are the brackets, :func:`green` the
factor exp(-j k R) / R; an engine's pair function (one element, one field point) combines
them with its own element and applies its prefactor where it chooses. :func:`radiation_kernels`
turns an element loader and a pair function into the launchable kernels: the one summation
loop every engine shares, with a four-point tiled variant for the CPU.

exp(-j k R) comes from :func:`cis`: Cody-Waite reduction of kR by 2 pi / 256 (a three-part
constant, exact products), a 256-entry table of cos and sin, and Taylor polynomials on the
remainder |r| <= pi / 256 (error below 1e-17); about 2e-16 in all, with no libm call.
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import Any

import numpy as np
import warp as wp

from raysim.optics.kernels.f64 import F64_HALF, F64_ONE, F64_THREE, F64_TWO, F64_ZERO  # noqa: F401

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
def green(k: wp.float64, R2: wp.float64, inv: wp.float64, table: wp.array(dtype=wp.vec2d)) -> wp.vec2d:
    """exp(-j k R) / R as (Re, Im), from R^2 and 1 / R."""
    e = cis(k * R2 * inv, table)
    return wp.vec2d(e[0] * inv, -e[1] * inv)


@wp.func
def electric_bracket(d: wp.vec3d, inv: wp.float64, u: wp.float64, pr: wp.vec3d, pi: wp.vec3d) -> vec6d:
    """a p - b (R_hat . p) R_hat for p = pr + j pi at d = P - S (1 / |d| = inv, u = 1 / (kR))."""
    u2 = u * u
    inv2 = inv * inv
    dr = wp.dot(d, pr) * inv2  # (R_hat . p) / R, real and imaginary parts
    di = wp.dot(d, pi) * inv2
    a_r = F64_ONE - u2  # a = a_r - j u
    b_r = F64_ONE - F64_THREE * u2  # b = b_r + j b_i
    b_i = -F64_THREE * u
    tr = b_r * dr - b_i * di
    ti = b_r * di + b_i * dr
    vr = a_r * pr + u * pi - tr * d
    vi = a_r * pi - u * pr - ti * d
    return vec6d(vr[0], vr[1], vr[2], vi[0], vi[1], vi[2])


@wp.func
def magnetic_bracket(d: wp.vec3d, inv: wp.float64, u: wp.float64, mr: wp.vec3d, mi: wp.vec3d) -> vec6d:
    """(1 - j u) R_hat x m for m = mr + j mi at d = P - S (1 / |d| = inv, u = 1 / (kR))."""
    cr = wp.cross(d, mr) * inv
    ci = wp.cross(d, mi) * inv
    vr = cr + u * ci
    vi = ci - u * cr
    return vec6d(vr[0], vr[1], vr[2], vi[0], vi[1], vi[2])


@wp.func
def times(v: vec6d, c: wp.vec2d) -> vec6d:
    """The complex 3-vector v times the complex scalar c."""
    return vec6d(c[0] * v[0] - c[1] * v[3], c[0] * v[1] - c[1] * v[4], c[0] * v[2] - c[1] * v[5],
                 c[0] * v[3] + c[1] * v[0], c[0] * v[4] + c[1] * v[1], c[0] * v[5] + c[1] * v[2])


# Four field points in the lanes of 4-vectors. Warp's CPU code keeps a pair function's vec3d
# and vec6d values as small structs and computes them one scalar at a time; written lane-wise
# (every quantity a vec4d over four field points, a field a 6 x 4 matrix) the compiler keeps
# them in vector registers, and PO's pairs run about 3.3 times as fast on the same cores (155.6
# against 47.3 M pairs/s on two cores, benchmarks/bench_po.py --skip-paper). Each lane does the one-point
# function's operations in the same order, so the sums agree with the one-point kernel's to
# rounding (bit for bit where the compiler fuses no multiply-add in either).
vec4d = wp.vec4d
#: a complex 3-vector at four field points: rows Re x, y, z, Im x, y, z; columns the points
lanes6 = wp.types.matrix(shape=(6, 4), dtype=wp.float64)
#: a complex scalar at four field points: rows Re, Im
lanes2 = wp.types.matrix(shape=(2, 4), dtype=wp.float64)
#: a real 3-vector at four field points: rows x, y, z
lanes3 = wp.types.matrix(shape=(3, 4), dtype=wp.float64)


@wp.func
def splat(x: wp.float64) -> vec4d:
    """x in all four lanes."""
    return vec4d(x, x, x, x)


@wp.func
def splat3(v: wp.vec3d) -> lanes3:
    """The vector v at all four points."""
    return wp.matrix_from_rows(splat(v[0]), splat(v[1]), splat(v[2]))


@wp.func
def cis4(x: vec4d, table: wp.array(dtype=wp.vec2d)) -> lanes2:
    """:func:`cis` lane by lane (the same operations in the same order)."""
    n = vec4d(wp.floor(x[0] * INV_STEP + F64_HALF), wp.floor(x[1] * INV_STEP + F64_HALF),
              wp.floor(x[2] * INV_STEP + F64_HALF), wp.floor(x[3] * INV_STEP + F64_HALF))
    r = ((x - n * STEP_1) - n * STEP_2) - n * STEP_3
    r2 = wp.cw_mul(r, r)
    s = r - wp.cw_mul(wp.cw_mul(r, r2), splat(INV_6) - r2 * INV_120)
    c = splat(F64_ONE) - wp.cw_mul(r2, splat(F64_HALF) - wp.cw_mul(r2, splat(INV_24) - r2 * INV_720))
    t0 = table[int(n[0]) & TABLE_MASK]
    t1 = table[int(n[1]) & TABLE_MASK]
    t2 = table[int(n[2]) & TABLE_MASK]
    t3 = table[int(n[3]) & TABLE_MASK]
    tc = vec4d(t0[0], t1[0], t2[0], t3[0])
    ts = vec4d(t0[1], t1[1], t2[1], t3[1])
    return wp.matrix_from_rows(wp.cw_mul(tc, c) - wp.cw_mul(ts, s), wp.cw_mul(ts, c) + wp.cw_mul(tc, s))


@wp.func
def green4(k: wp.float64, R2: vec4d, inv: vec4d, table: wp.array(dtype=wp.vec2d)) -> lanes2:
    """:func:`green` lane by lane."""
    e = cis4(wp.cw_mul(R2 * k, inv), table)
    return wp.matrix_from_rows(wp.cw_mul(e[0], inv), -wp.cw_mul(e[1], inv))


@wp.struct
class Offsets4:
    """d = P - S at four field points (m, x, y, z each a vec4d), R^2, 1 / R and u = 1 / (kR)."""

    x: vec4d
    y: vec4d
    z: vec4d
    R2: vec4d
    inv: vec4d
    u: vec4d


@wp.func
def offsets4(px: vec4d, py: vec4d, pz: vec4d, s: wp.vec3d, k_inv: wp.float64) -> Offsets4:
    """:class:`Offsets4` of the element at S seen from the points (px, py, pz)."""
    o = Offsets4()
    o.x = px - splat(s[0])
    o.y = py - splat(s[1])
    o.z = pz - splat(s[2])
    o.R2 = wp.cw_mul(o.x, o.x) + wp.cw_mul(o.y, o.y) + wp.cw_mul(o.z, o.z)
    o.inv = vec4d(F64_ONE / wp.sqrt(o.R2[0]), F64_ONE / wp.sqrt(o.R2[1]), F64_ONE / wp.sqrt(o.R2[2]),
                  F64_ONE / wp.sqrt(o.R2[3]))
    o.u = o.inv * k_inv
    return o


@wp.func
def electric_bracket4(d: Offsets4, pr: lanes3, pi: lanes3) -> lanes6:
    """:func:`electric_bracket` lane by lane, for a moment p = pr + j pi that may differ from
    lane to lane (the transposed sum's weights; :func:`splat3` of an element's own)."""
    u2 = wp.cw_mul(d.u, d.u)
    inv2 = wp.cw_mul(d.inv, d.inv)
    dr = wp.cw_mul(wp.cw_mul(d.x, pr[0]) + wp.cw_mul(d.y, pr[1]) + wp.cw_mul(d.z, pr[2]), inv2)
    di = wp.cw_mul(wp.cw_mul(d.x, pi[0]) + wp.cw_mul(d.y, pi[1]) + wp.cw_mul(d.z, pi[2]), inv2)
    a_r = splat(F64_ONE) - u2
    b_r = splat(F64_ONE) - u2 * F64_THREE
    b_i = -(d.u * F64_THREE)
    tr = wp.cw_mul(b_r, dr) - wp.cw_mul(b_i, di)
    ti = wp.cw_mul(b_r, di) + wp.cw_mul(b_i, dr)
    return wp.matrix_from_rows(
        wp.cw_mul(a_r, pr[0]) + wp.cw_mul(d.u, pi[0]) - wp.cw_mul(tr, d.x),
        wp.cw_mul(a_r, pr[1]) + wp.cw_mul(d.u, pi[1]) - wp.cw_mul(tr, d.y),
        wp.cw_mul(a_r, pr[2]) + wp.cw_mul(d.u, pi[2]) - wp.cw_mul(tr, d.z),
        wp.cw_mul(a_r, pi[0]) - wp.cw_mul(d.u, pr[0]) - wp.cw_mul(ti, d.x),
        wp.cw_mul(a_r, pi[1]) - wp.cw_mul(d.u, pr[1]) - wp.cw_mul(ti, d.y),
        wp.cw_mul(a_r, pi[2]) - wp.cw_mul(d.u, pr[2]) - wp.cw_mul(ti, d.z))


@wp.func
def magnetic_bracket4(d: Offsets4, mr: wp.vec3d, mi: wp.vec3d) -> lanes6:
    """:func:`magnetic_bracket` lane by lane (the cross products as ``wp.cross`` forms them)."""
    crx = wp.cw_mul(d.y * mr[2] - d.z * mr[1], d.inv)
    cry = wp.cw_mul(d.z * mr[0] - d.x * mr[2], d.inv)
    crz = wp.cw_mul(d.x * mr[1] - d.y * mr[0], d.inv)
    cix = wp.cw_mul(d.y * mi[2] - d.z * mi[1], d.inv)
    ciy = wp.cw_mul(d.z * mi[0] - d.x * mi[2], d.inv)
    ciz = wp.cw_mul(d.x * mi[1] - d.y * mi[0], d.inv)
    return wp.matrix_from_rows(
        crx + wp.cw_mul(d.u, cix), cry + wp.cw_mul(d.u, ciy), crz + wp.cw_mul(d.u, ciz),
        cix - wp.cw_mul(d.u, crx), ciy - wp.cw_mul(d.u, cry), ciz - wp.cw_mul(d.u, crz))


@wp.func
def times4(v: lanes6, c: lanes2) -> lanes6:
    """:func:`times` lane by lane."""
    return wp.matrix_from_rows(
        wp.cw_mul(c[0], v[0]) - wp.cw_mul(c[1], v[3]), wp.cw_mul(c[0], v[1]) - wp.cw_mul(c[1], v[4]),
        wp.cw_mul(c[0], v[2]) - wp.cw_mul(c[1], v[5]), wp.cw_mul(c[0], v[3]) + wp.cw_mul(c[1], v[0]),
        wp.cw_mul(c[0], v[4]) + wp.cw_mul(c[1], v[1]), wp.cw_mul(c[0], v[5]) + wp.cw_mul(c[1], v[2]))


def radiation_kernels(load: Any, pair: Any, pair4: Any = None) -> tuple[Any, Any]:
    """The summation kernels of one kind of element: ``(radiate, radiate4)``.

    ``load(src, s)`` (a ``wp.func``) reads element ``s`` of the engine's column-wise float64
    array ``src``; ``pair(P, element, k, k_inv, table)`` returns its field at P as ``vec6d``;
    ``pair4(px, py, pz, element, k, k_inv, table)``, where a kind has one, the same at four
    points in lanes (``vec4d`` coordinates, a :data:`lanes6` field).
    Both kernels take ``(field, src, begin, end, k, k_inv, table, E, offset)`` and add the
    sum over elements ``begin..end-1`` into ``E`` (6, n): ``radiate`` one field point per
    thread, ``radiate4`` the four points 4t..4t+3 per thread t (each element is loaded once
    for four points, and with ``pair4`` summed in vector lanes). The trailing ``offset`` lets
    :func:`raysim.optics.runtime.launch` split a launch across CPU threads.
    """

    @wp.kernel(module="unique")
    def radiate(
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
        i = wp.tid() + offset
        p = wp.vec3d(field[0, i], field[1, i], field[2, i])
        acc = vec6d()
        for s in range(begin, end):
            acc += pair(p, load(src, s), k, k_inv, table)
        for c in range(6):
            E[c, i] = E[c, i] + acc[c]

    @wp.kernel(module="unique")
    def radiate4(
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
        t = (wp.tid() + offset) * 4
        if wp.static(pair4 is not None):  # decided when the kernel is built
            px = vec4d(field[0, t], field[0, t + 1], field[0, t + 2], field[0, t + 3])
            py = vec4d(field[1, t], field[1, t + 1], field[1, t + 2], field[1, t + 3])
            pz = vec4d(field[2, t], field[2, t + 1], field[2, t + 2], field[2, t + 3])
            acc = lanes6()
            for s in range(begin, end):
                acc += pair4(px, py, pz, load(src, s), k, k_inv, table)
            for c in range(6):
                for j in range(4):
                    E[c, t + j] = E[c, t + j] + acc[c, j]
        else:
            p0 = wp.vec3d(field[0, t], field[1, t], field[2, t])
            p1 = wp.vec3d(field[0, t + 1], field[1, t + 1], field[2, t + 1])
            p2 = wp.vec3d(field[0, t + 2], field[1, t + 2], field[2, t + 2])
            p3 = wp.vec3d(field[0, t + 3], field[1, t + 3], field[2, t + 3])
            a0 = vec6d()
            a1 = vec6d()
            a2 = vec6d()
            a3 = vec6d()
            for s in range(begin, end):
                e = load(src, s)
                a0 += pair(p0, e, k, k_inv, table)
                a1 += pair(p1, e, k, k_inv, table)
                a2 += pair(p2, e, k, k_inv, table)
                a3 += pair(p3, e, k, k_inv, table)
            for c in range(6):
                E[c, t] = E[c, t] + a0[c]
                E[c, t + 1] = E[c, t + 1] + a1[c]
                E[c, t + 2] = E[c, t + 2] + a2[c]
                E[c, t + 3] = E[c, t + 3] + a3[c]

    return radiate, radiate4


vec8d = wp.types.vector(length=8, dtype=wp.float64)
#: eight real numbers at four field points (the transposed sums' pairs in lanes)
lanes8 = wp.types.matrix(shape=(8, 4), dtype=wp.float64)


def adjoint_kernel(load: Any, pair: Any, pair4: Any = None) -> Any:
    """The transposed sum of one kind of element: per element, over the field points.

    ``field`` (9, n) holds each field point P and a complex weight b (Re 3, Im 3);
    ``pair(P, b_re, b_im, element, k, k_inv, table)`` returns up to eight real numbers
    (``vec8d``) that are linear in b; ``pair4(px, py, pz, b_re, b_im, element, k, k_inv,
    table)``, where a kind has one, the same at four points in vector lanes (``lanes3``
    weights, a :data:`lanes8` result). The kernel adds their sum over the points
    ``begin..end-1`` to ``out[:, s]`` (8, n_elements) for element s = tid + offset: the
    adjoint of a radiation sum, field points as sources. With ``pair4`` the points are taken
    four at a time, so end - begin must be a multiple of four (pad with zero weights).
    """

    @wp.kernel(module="unique")
    def adjoint(
        field: wp.array2d(dtype=wp.float64),
        src: wp.array2d(dtype=wp.float64),
        begin: int,
        end: int,
        k: wp.float64,
        k_inv: wp.float64,
        table: wp.array(dtype=wp.vec2d),
        out: wp.array2d(dtype=wp.float64),
        offset: int,
    ):
        s = wp.tid() + offset
        e = load(src, s)
        if wp.static(pair4 is not None):  # decided when the kernel is built
            lanes = lanes8()
            for i in range(begin, end, 4):
                px = vec4d(field[0, i], field[0, i + 1], field[0, i + 2], field[0, i + 3])
                py = vec4d(field[1, i], field[1, i + 1], field[1, i + 2], field[1, i + 3])
                pz = vec4d(field[2, i], field[2, i + 1], field[2, i + 2], field[2, i + 3])
                bre = wp.matrix_from_rows(
                    vec4d(field[3, i], field[3, i + 1], field[3, i + 2], field[3, i + 3]),
                    vec4d(field[4, i], field[4, i + 1], field[4, i + 2], field[4, i + 3]),
                    vec4d(field[5, i], field[5, i + 1], field[5, i + 2], field[5, i + 3]))
                bim = wp.matrix_from_rows(
                    vec4d(field[6, i], field[6, i + 1], field[6, i + 2], field[6, i + 3]),
                    vec4d(field[7, i], field[7, i + 1], field[7, i + 2], field[7, i + 3]),
                    vec4d(field[8, i], field[8, i + 1], field[8, i + 2], field[8, i + 3]))
                lanes += pair4(px, py, pz, bre, bim, e, k, k_inv, table)
            for c in range(8):
                out[c, s] = out[c, s] + ((lanes[c, 0] + lanes[c, 1]) + (lanes[c, 2] + lanes[c, 3]))
        else:
            acc = vec8d()
            for i in range(begin, end):
                p = wp.vec3d(field[0, i], field[1, i], field[2, i])
                bre = wp.vec3d(field[3, i], field[4, i], field[5, i])
                bim = wp.vec3d(field[6, i], field[7, i], field[8, i])
                acc += pair(p, bre, bim, e, k, k_inv, table)
            for c in range(8):
                out[c, s] = out[c, s] + acc[c]

    return adjoint


@wp.func
def store_complex(E: wp.array2d(dtype=wp.float64), t: int, v: vec6d):
    """Row t of ``E`` from v (Re x, y, z, Im x, y, z) as three complex numbers in numpy's
    complex128 layout (Re x, Im x, Re y, Im y, Re z, Im z)."""
    E[t, 0] = v[0]
    E[t, 1] = v[3]
    E[t, 2] = v[1]
    E[t, 3] = v[4]
    E[t, 4] = v[2]
    E[t, 5] = v[5]


@wp.func
def store_node(E: wp.array2d(dtype=wp.float64), base: int, slots: wp.array2d(dtype=wp.int32), node: int,
               v: vec6d):
    """v at the whole-grid rows ``base + slots[node, 0]`` and ``base + slots[node, 1]`` of
    ``E`` (each skipped where it is -1): a computed node and the mirrored node that is the same
    point of the sphere."""
    for j in range(2):
        row = slots[node, j]
        if row >= 0:
            store_complex(E, base + row, v)


def segment_kernel(load: Any, pair: Any, pair4: Any = None) -> tuple[Any, Any]:
    """The leaf sums of the fast radiator for one kind of element (same ``load``, ``pair`` and
    ``pair4``): ``(radiate_segments, radiate_segments4)``, one node or four nodes per thread
    (in vector lanes where the kind has ``pair4``).

    Every cluster (leaf) sees the same ``nodes`` (3, n_nodes) field points (the grid's rows
    theta <= pi, padded); thread t is node ``t % n_nodes`` of leaf ``t // n_nodes`` and sums
    the leaf's elements ``begins[leaf]..ends[leaf]-1`` of ``src``, raw (before the kind's
    prefactor) as :func:`radiation_kernels` does for one point, times exp(+j k |P -
    centres[leaf]|) (the phase of the leaf's centre taken out). The value goes to the leaf's
    whole grid in ``E`` (n_leaves * n_full, 6), rows ``slots[node]`` of it (:func:`store_node`:
    the node's own place and its mirror's; padding nodes have none), as three complex numbers
    (Re x, Im x, Re y, Im y, Re z, Im z: numpy's complex128 layout).
    """

    @wp.kernel(module="unique")
    def radiate_segments(
        nodes: wp.array2d(dtype=wp.float64),
        begins: wp.array(dtype=wp.int32),
        ends: wp.array(dtype=wp.int32),
        centres: wp.array2d(dtype=wp.float64),
        n_nodes: int,
        src: wp.array2d(dtype=wp.float64),
        k: wp.float64,
        k_inv: wp.float64,
        table: wp.array(dtype=wp.vec2d),
        slots: wp.array2d(dtype=wp.int32),
        n_full: int,
        E: wp.array2d(dtype=wp.float64),
        offset: int,
    ):
        t = wp.tid() + offset
        leaf = t // n_nodes
        node = t - leaf * n_nodes
        p = wp.vec3d(nodes[0, node], nodes[1, node], nodes[2, node])
        acc = vec6d()
        for s in range(begins[leaf], ends[leaf]):
            acc += pair(p, load(src, s), k, k_inv, table)
        d = p - wp.vec3d(centres[leaf, 0], centres[leaf, 1], centres[leaf, 2])
        store_node(E, leaf * n_full, slots, node, times(acc, cis(k * wp.sqrt(wp.dot(d, d)), table)))

    @wp.kernel(module="unique")
    def radiate_segments4(
        nodes: wp.array2d(dtype=wp.float64),
        begins: wp.array(dtype=wp.int32),
        ends: wp.array(dtype=wp.int32),
        centres: wp.array2d(dtype=wp.float64),
        n_nodes: int,
        src: wp.array2d(dtype=wp.float64),
        k: wp.float64,
        k_inv: wp.float64,
        table: wp.array(dtype=wp.vec2d),
        slots: wp.array2d(dtype=wp.int32),
        n_full: int,
        E: wp.array2d(dtype=wp.float64),
        offset: int,
    ):
        # four nodes 4j..4j+3 of one leaf per thread (n_nodes a multiple of four): each element
        # is loaded once for four nodes, as radiate4 does
        t = (wp.tid() + offset) * 4
        leaf = t // n_nodes
        node = t - leaf * n_nodes
        c = wp.vec3d(centres[leaf, 0], centres[leaf, 1], centres[leaf, 2])
        base = leaf * n_full
        if wp.static(pair4 is not None):  # decided when the kernel is built
            px = vec4d(nodes[0, node], nodes[0, node + 1], nodes[0, node + 2], nodes[0, node + 3])
            py = vec4d(nodes[1, node], nodes[1, node + 1], nodes[1, node + 2], nodes[1, node + 3])
            pz = vec4d(nodes[2, node], nodes[2, node + 1], nodes[2, node + 2], nodes[2, node + 3])
            acc = lanes6()
            for s in range(begins[leaf], ends[leaf]):
                acc += pair4(px, py, pz, load(src, s), k, k_inv, table)
            for j in range(4):
                p = wp.vec3d(px[j], py[j], pz[j])
                v = vec6d(acc[0, j], acc[1, j], acc[2, j], acc[3, j], acc[4, j], acc[5, j])
                store_node(E, base, slots, node + j, times(v, cis(wp.length(p - c) * k, table)))
        else:
            p0 = wp.vec3d(nodes[0, node], nodes[1, node], nodes[2, node])
            p1 = wp.vec3d(nodes[0, node + 1], nodes[1, node + 1], nodes[2, node + 1])
            p2 = wp.vec3d(nodes[0, node + 2], nodes[1, node + 2], nodes[2, node + 2])
            p3 = wp.vec3d(nodes[0, node + 3], nodes[1, node + 3], nodes[2, node + 3])
            a0 = vec6d()
            a1 = vec6d()
            a2 = vec6d()
            a3 = vec6d()
            for s in range(begins[leaf], ends[leaf]):
                e = load(src, s)
                a0 += pair(p0, e, k, k_inv, table)
                a1 += pair(p1, e, k, k_inv, table)
                a2 += pair(p2, e, k, k_inv, table)
                a3 += pair(p3, e, k, k_inv, table)
            store_node(E, base, slots, node, times(a0, cis(wp.length(p0 - c) * k, table)))
            store_node(E, base, slots, node + 1, times(a1, cis(wp.length(p1 - c) * k, table)))
            store_node(E, base, slots, node + 2, times(a2, cis(wp.length(p2 - c) * k, table)))
            store_node(E, base, slots, node + 3, times(a3, cis(wp.length(p3 - c) * k, table)))

    return radiate_segments, radiate_segments4


def segment_adjoint_kernel(load: Any, pair: Any, pair4: Any = None) -> Any:
    """The leaf step of the fast radiator's transposed sum for one kind of element (the
    ``load``, ``pair`` and ``pair4`` of :func:`adjoint_kernel`): one thread per element.

    Every leaf sees the same ``nodes`` (3, n_nodes) field points (m). Element s (in leaf order)
    belongs to leaf ``leaf_of[s]`` and sums ``pair(P_n, b_n, element)`` over that leaf's nodes,
    b_n = ``weights[leaf * n_nodes + n]`` (Re 3, Im 3): the leaf's anterpolated weights with the
    leaf centre's phase exp(+j k |P_n - c_leaf|) already put back (once per node, by the
    caller, not once per element). The sum is written to ``out[:, s]`` (8, n_elements). With
    ``pair4`` the nodes are taken four at a time (n_nodes a multiple of four: pad with zero
    weights).
    """

    @wp.kernel(module="unique")
    def adjoint_segments(
        nodes: wp.array2d(dtype=wp.float64),
        leaf_of: wp.array(dtype=wp.int32),
        weights: wp.array2d(dtype=wp.float64),
        n_nodes: int,
        src: wp.array2d(dtype=wp.float64),
        k: wp.float64,
        k_inv: wp.float64,
        table: wp.array(dtype=wp.vec2d),
        out: wp.array2d(dtype=wp.float64),
        offset: int,
    ):
        s = wp.tid() + offset
        e = load(src, s)
        base = leaf_of[s] * n_nodes
        if wp.static(pair4 is not None):  # decided when the kernel is built
            lanes = lanes8()
            for n in range(0, n_nodes, 4):
                px = vec4d(nodes[0, n], nodes[0, n + 1], nodes[0, n + 2], nodes[0, n + 3])
                py = vec4d(nodes[1, n], nodes[1, n + 1], nodes[1, n + 2], nodes[1, n + 3])
                pz = vec4d(nodes[2, n], nodes[2, n + 1], nodes[2, n + 2], nodes[2, n + 3])
                row = base + n
                bre = wp.matrix_from_rows(
                    vec4d(weights[row, 0], weights[row + 1, 0], weights[row + 2, 0], weights[row + 3, 0]),
                    vec4d(weights[row, 1], weights[row + 1, 1], weights[row + 2, 1], weights[row + 3, 1]),
                    vec4d(weights[row, 2], weights[row + 1, 2], weights[row + 2, 2], weights[row + 3, 2]))
                bim = wp.matrix_from_rows(
                    vec4d(weights[row, 3], weights[row + 1, 3], weights[row + 2, 3], weights[row + 3, 3]),
                    vec4d(weights[row, 4], weights[row + 1, 4], weights[row + 2, 4], weights[row + 3, 4]),
                    vec4d(weights[row, 5], weights[row + 1, 5], weights[row + 2, 5], weights[row + 3, 5]))
                lanes += pair4(px, py, pz, bre, bim, e, k, k_inv, table)
            for c in range(8):
                out[c, s] = (lanes[c, 0] + lanes[c, 1]) + (lanes[c, 2] + lanes[c, 3])
        else:
            acc = vec8d()
            for n in range(n_nodes):
                p = wp.vec3d(nodes[0, n], nodes[1, n], nodes[2, n])
                row = base + n
                bre = wp.vec3d(weights[row, 0], weights[row, 1], weights[row, 2])
                bim = wp.vec3d(weights[row, 3], weights[row, 4], weights[row, 5])
                acc += pair(p, bre, bim, e, k, k_inv, table)
            for c in range(8):
                out[c, s] = acc[c]

    return adjoint_segments
