"""Warp kernels of the physical-optics engine (see :mod:`raysim.optics.po`): currents and radiation.

Time convention exp(+j w t), SI units, reflector frame. Current elements are stored column-wise
in a ``(9, N)`` float64 array: rows 0-2 the position (m), rows 3-5 and 6-8 the real and
imaginary parts of the element's moment (J dA in A m for electric elements, M dA in V m for
magnetic ones). The kernels sum, without the constant prefactors that
:class:`raysim.optics.radiator.Radiator` applies once,

- electric elements: exp(-j k R) / R [a p - b (R_hat . p) R_hat],
- magnetic elements: exp(-j k R) / R (1 - j/(kR)) R_hat x m,

the brackets of :mod:`raysim.optics.kernels.radiation` (which names the reference). Every
kernel takes a trailing ``offset: int`` and indexes ``wp.tid() + offset`` so that
:func:`raysim.optics.runtime.launch` can split it across CPU threads.
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.f64 import F64_ONE, F64_TWO
from raysim.optics.kernels.radiation import (
    electric_bracket,
    electric_bracket4,
    green,
    green4,
    lanes6,
    magnetic_bracket,
    magnetic_bracket4,
    offsets4,
    radiation_kernels,
    segment_kernel,
    splat3,
    times,
    times4,
    vec4d,
    vec6d,
)

wp.set_module_options({"enable_backward": False})

ROWS = 9  # position (3), Re moment (3), Im moment (3)


@wp.struct
class Dipole:
    """One point current element: position r (m), moment re + j im (A m or V m)."""

    r: wp.vec3d
    re: wp.vec3d
    im: wp.vec3d


@wp.func
def load_dipole(src: wp.array2d(dtype=wp.float64), s: int) -> Dipole:
    e = Dipole()
    e.r = wp.vec3d(src[0, s], src[1, s], src[2, s])
    e.re = wp.vec3d(src[3, s], src[4, s], src[5, s])
    e.im = wp.vec3d(src[6, s], src[7, s], src[8, s])
    return e


@wp.func
def electric_pair(p: wp.vec3d, e: Dipole, k: wp.float64, k_inv: wp.float64,
                  table: wp.array(dtype=wp.vec2d)) -> vec6d:
    """exp(-jkR)/R [a p - b (R_hat . p) R_hat] at P of the electric element e."""
    d = p - e.r
    R2 = wp.dot(d, d)
    inv = F64_ONE / wp.sqrt(R2)
    return times(electric_bracket(d, inv, inv * k_inv, e.re, e.im), green(k, R2, inv, table))


@wp.func
def magnetic_pair(p: wp.vec3d, e: Dipole, k: wp.float64, k_inv: wp.float64,
                  table: wp.array(dtype=wp.vec2d)) -> vec6d:
    """exp(-jkR)/R (1 - j/(kR)) R_hat x m at P of the magnetic element e."""
    d = p - e.r
    R2 = wp.dot(d, d)
    inv = F64_ONE / wp.sqrt(R2)
    return times(magnetic_bracket(d, inv, inv * k_inv, e.re, e.im), green(k, R2, inv, table))


@wp.func
def electric_pair4(px: vec4d, py: vec4d, pz: vec4d, e: Dipole, k: wp.float64, k_inv: wp.float64,
                   table: wp.array(dtype=wp.vec2d)) -> lanes6:
    """:func:`electric_pair` at four points in vector lanes."""
    d = offsets4(px, py, pz, e.r, k_inv)
    return times4(electric_bracket4(d, splat3(e.re), splat3(e.im)), green4(k, d.R2, d.inv, table))


@wp.func
def magnetic_pair4(px: vec4d, py: vec4d, pz: vec4d, e: Dipole, k: wp.float64, k_inv: wp.float64,
                   table: wp.array(dtype=wp.vec2d)) -> lanes6:
    """:func:`magnetic_pair` at four points in vector lanes."""
    d = offsets4(px, py, pz, e.r, k_inv)
    return times4(magnetic_bracket4(d, e.re, e.im), green4(k, d.R2, d.inv, table))


radiate_electric, radiate_electric4 = radiation_kernels(load_dipole, electric_pair, electric_pair4)
radiate_magnetic, radiate_magnetic4 = radiation_kernels(load_dipole, magnetic_pair, magnetic_pair4)
segments_electric = segment_kernel(load_dipole, electric_pair, electric_pair4)
segments_magnetic = segment_kernel(load_dipole, magnetic_pair, magnetic_pair4)


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
