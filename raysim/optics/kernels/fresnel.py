"""The Fresnel-zone window sums of :mod:`raysim.optics.fresnel`, one field point per thread.

Reflector frame, metres, float64 throughout. For field point P with specular point s (its
aperture coordinates), the window is the lattice x0 + (i, j) h around s, every ``stride``-th
point out to ``n_half`` strides; at each lattice point r = (X, Y, (X^2 + Y^2) / 4F) on the
ideal paraboloid the kernel adds, with w = exp(-|r_xy - s|^2 / 2 sigma^2) / |P - r| and
phi = -k (psi(r) - psi(s)), psi = -z + |P - r| (on-axis incidence, k_hat = -z):

    den += w exp(j phi),    num += w q delta exp(j phi),    q = d psi / dz = -1 - (P_z - z) / |P - r|,.
"""

from __future__ import annotations

import warp as wp

from raysim.optics.kernels.f64 import F64_HALF, F64_ONE, F64_ZERO

wp.set_module_options({"enable_backward": False})


@wp.func
def _path(P: wp.vec3d, X: wp.float64, Y: wp.float64, four_F: wp.float64) -> wp.vec3d:
    """(psi, q, |P - r|) at the paraboloid point over (X, Y)."""
    Z = (X * X + Y * Y) / four_F
    dx = P[0] - X
    dy = P[1] - Y
    dz = P[2] - Z
    L = wp.sqrt(dx * dx + dy * dy + dz * dz)
    return wp.vec3d(L - Z, -F64_ONE - dz / L, L)


@wp.kernel
def window_sums(
    points: wp.array(dtype=wp.vec3d),
    centres: wp.array(dtype=wp.vec2d),
    sigma: wp.array(dtype=wp.float64),
    n_half: wp.array(dtype=wp.int32),
    stride: wp.array(dtype=wp.int32),
    delta: wp.array2d(dtype=wp.float64),
    x0: wp.float64,
    h: wp.float64,
    four_F: wp.float64,
    k: wp.float64,
    num: wp.array(dtype=wp.vec2d),
    den: wp.array(dtype=wp.vec2d),
    offset: int,
):
    """num[i], den[i] (complex as (re, im)) of field point i's window (module docstring)."""
    i = wp.tid() + offset
    P = points[i]
    s = centres[i]
    n = n_half[i]
    m = stride[i]
    inv_2s2 = F64_HALF / (sigma[i] * sigma[i])
    ps = _path(P, s[0], s[1], four_F)
    ic = int(wp.round((s[0] - x0) / h))
    jc = int(wp.round((s[1] - x0) / h))
    nx = delta.shape[1]
    ny = delta.shape[0]
    nr = F64_ZERO
    ni = F64_ZERO
    dr = F64_ZERO
    di = F64_ZERO
    for a in range(-n, n + 1):
        ii = ic + a * m
        if ii >= 0 and ii < nx:
            X = x0 + wp.float64(ii) * h
            ux = X - s[0]
            for b in range(-n, n + 1):
                jj = jc + b * m
                if jj >= 0 and jj < ny:
                    Y = x0 + wp.float64(jj) * h
                    uy = Y - s[1]
                    p = _path(P, X, Y, four_F)
                    w = wp.exp(-(ux * ux + uy * uy) * inv_2s2) / p[2]
                    phase = -k * (p[0] - ps[0])
                    c = w * wp.cos(phase)
                    sn = w * wp.sin(phase)
                    qd = p[1] * delta[jj, ii]
                    dr += c
                    di += sn
                    nr += qd * c
                    ni += qd * sn
    num[i] = wp.vec2d(nr, ni)
    den[i] = wp.vec2d(dr, di)
