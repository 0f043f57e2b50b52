"""The PO field's exact linearisation in the surface: Jacobian-vector products and their adjoint.

Frame and units of docs/physics.md (reflector frame, metres, SI fields); time convention exp(+j w t);
the PO engine of :mod:`raysim.optics.po`, on a reflector with a smooth surface z = h(x, y).
Its field at P is the quadrature sum over the lit samples s (:mod:`raysim.surface.quadrature`)

    E(P) = C G(P - r_s) m_s,   m_s = (2 / eta) (A_s x h_hat) exp(-j k k_hat . r_s),
    r_s = (x_s, y_s, h(x_s, y_s)),   A_s = w_s (-h_x, -h_y, 1),   C = -j k eta / (4 pi),

with fixed footprints (x_s, y_s) and projected weights w_s. A perturbation dh of the surface
moves each sample along z by dz_s = dh(x_s, y_s), turns its vector area by
dA_s = -w_s (dh_x, dh_y, 0) and changes its incident phase, so

    dE(P) = C sum_s [G(P - r_s) p_s + D_{-dz_s z_hat}[G(P - r_s) m_s]],
    p_s = -j k (k_hat . z_hat) dz_s m_s + (2 / eta) (dA_s x h_hat) exp(-j k k_hat . r_s):

again a radiation sum, of the ``shift`` elements of :mod:`raysim.optics.kernels.po_derivative`
(one PO radiation's cost). The adjoint takes complex weights c(P) on the field and returns, per
sample, the real gradients of Re sum_P conj(c(P)) . dE(P) with respect to (dz_s, dh_x, dh_y):
the transposed sum, field points as sources (about one more radiation). The lit set is the
one of the state the elements were made at (a perturbation small enough for a derivative
does not move a shadow boundary across a sample).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.errors import RaysimError
from raysim.optics import runtime
from raysim.optics.bvh import ReflectorBVH
from raysim.optics.fast.radiator import DEFAULT_TOL, make_radiator
from raysim.optics.illumination import ETA0, Illumination
from raysim.optics.radiator import PREFACTORS, Radiator
from raysim.optics.shadow_edge import lit_samples
from raysim.surface.mesh import Reflector
from raysim.surface.quadrature import Targets, plan

Z_HAT = np.array([0.0, 0.0, 1.0])


@dataclass
class SurfaceElements:
    """The lit PO samples of one reflector state and what their derivatives need.

    ``x``, ``y`` (n,) footprints (m); ``r`` (n, 3) positions (m); ``m`` (n, 3) complex
    moments J dA (A m); ``dm_dz``, ``dm_dhx``, ``dm_dhy`` (n, 3) complex: the moment's change
    per metre of dz and per unit of each slope change (A m per m, A m).
    """

    x: NDArray[np.float64]
    y: NDArray[np.float64]
    r: NDArray[np.float64]
    m: NDArray[np.complex128]
    dm_dz: NDArray[np.complex128]
    dm_dhx: NDArray[np.complex128]
    dm_dhy: NDArray[np.complex128]
    k: float
    seconds: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.x)


def surface_elements(reflector: Reflector, wave: Illumination, samples_per_wavelength: float,
                     device: str | None = "cpu", targets: Targets | None = None) -> SurfaceElements:
    """The PO samples of ``reflector`` (which must have a smooth surface) under ``wave``.

    The same samples, lit test and lit-side rule as :func:`raysim.optics.po.po_elements`
    (``targets``: as :class:`raysim.optics.sources.Sources`'s, for the same quadrature).
    """
    if reflector.surface is None:
        raise RaysimError("the PO Jacobian needs a reflector with a smooth surface")
    dev = runtime.resolve_device(device)
    quadrature = plan(reflector, wave.wavelength, samples_per_wavelength, targets)
    bvh = ReflectorBVH.build(reflector, dev)
    h_hat = wave.h_hat
    v = reflector.vertices[reflector.faces]
    back_lit = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]) @ wave.k_hat > 0.0
    parts = []
    for samples in quadrature.chunks():
        lit, _ = lit_samples(quadrature, samples, bvh, wave.k_hat)
        flip = np.where(back_lit[lit.face], -1.0, 1.0)[:, None]
        parts.append((lit.points, lit.area * flip))
    points = np.concatenate([p for p, _ in parts])
    area = np.concatenate([a for _, a in parts])
    phase = np.exp(-1j * wave.k * (points @ wave.k_hat))[:, None]
    scale = 2.0 / ETA0
    m = scale * np.cross(area, h_hat) * phase
    w = area[:, 2:3]
    zero = np.zeros_like(w)
    dm_dhx = scale * np.cross(np.hstack([-w, zero, zero]), h_hat) * phase
    dm_dhy = scale * np.cross(np.hstack([zero, -w, zero]), h_hat) * phase
    dm_dz = -1j * wave.k * float(wave.k_hat @ Z_HAT) * m
    return SurfaceElements(points[:, 0].copy(), points[:, 1].copy(), points, m, dm_dz, dm_dhx,
                           dm_dhy, wave.k)


def radiate(elements: SurfaceElements, points: ArrayLike, device: str | None = "cpu",
            progress=None) -> NDArray[np.complex128]:
    """E (n, 3) of the elements' moments at ``points`` (the PO field of that state, V/m)."""
    radiator = Radiator(points, elements.k, device)
    packed = np.vstack([elements.r.T, elements.m.real.T, elements.m.imag.T])
    radiator.add_packed(packed, "electric", progress)
    return radiator.field()


def jvp(elements: SurfaceElements, points: ArrayLike, dz: ArrayLike, dhx: ArrayLike,
        dhy: ArrayLike, device: str | None = "cpu", progress=None, radiator: str = "direct",
        tol: float = DEFAULT_TOL, centre: ArrayLike | None = None,
        force: bool = False) -> NDArray[np.complex128]:
    """dE (n, 3) at ``points`` for per-sample dz (m) and slope changes dhx, dhy (module docs).

    ``radiator``, ``tol``, ``centre`` (the sphere's centre, m), ``force``: as
    :func:`raysim.optics.fast.radiator.make_radiator` (the fast sum of the shift elements)."""
    dz, dhx, dhy = (np.asarray(a, dtype=np.float64)[:, None] for a in (dz, dhx, dhy))
    p = elements.dm_dz * dz + elements.dm_dhx * dhx + elements.dm_dhy * dhy
    packed = np.vstack([elements.r.T, elements.m.real.T, elements.m.imag.T, p.real.T, p.imag.T,
                        (dz * Z_HAT[None, :]).T])
    rad = make_radiator(points, elements.k, device, radiator=radiator, tol=tol, centre=centre, force=force)
    rad.add_packed(packed, "shift", progress)
    return rad.field()


def vjp(elements: SurfaceElements, points: ArrayLike, c: ArrayLike, device: str | None = "cpu",
        block: int | None = None, radiator: str = "direct", tol: float = DEFAULT_TOL,
        centre: ArrayLike | None = None, force: bool = False,
        info: dict | None = None) -> tuple[NDArray, NDArray, NDArray]:
    """Gradients (n_samples,) of Re sum_P conj(c(P)) . dE(P) in dz_s, dhx_s and dhy_s.

    ``c`` (n_points, 3) complex weights on the field at ``points`` (m). ``radiator="fast"``
    with ``centre`` (the sphere's centre, m): the transposed multilevel sum
    (:func:`raysim.optics.fast.adjoint.transposed_sum`, tolerance ``tol``, ``force`` as
    :func:`raysim.optics.fast.radiator.make_radiator`), where its rules choose it; otherwise
    the direct transposed sum. ``info``, when given, receives ``method``.
    """
    from raysim.optics.fast.radiator import RADIATORS
    from raysim.optics.kernels import po_derivative, radiation

    if radiator not in RADIATORS:
        raise RaysimError(f"unknown radiator {radiator!r}: use one of {', '.join(RADIATORS)}")
    wp = runtime.init()
    dev = runtime.resolve_device(device)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    prefactor = PREFACTORS["shift"](elements.k)  # the moving elements' (electric) constant
    b = prefactor * np.conj(np.asarray(c, dtype=np.complex128).reshape(-1, 3))
    n = len(elements)
    sources = np.vstack([elements.r.T, elements.m.real.T, elements.m.imag.T,
                         np.repeat(-Z_HAT[:, None], n, axis=1)])
    start = time.perf_counter()
    acc = None
    if radiator == "fast" and centre is not None:
        from raysim.optics.fast import adjoint

        acc = adjoint.transposed_sum(po_derivative.segments_adjoint, sources, pts, b, elements.k,
                                     centre, dev, tol=tol, force=force, info=info)
    if acc is None:
        if info is not None:
            info["method"] = "direct"
        # the kernel takes the points four at a time (vector lanes): pad them to a multiple of
        # four with copies of the last point and zero weights, which add exactly nothing
        pad = -len(pts) % 4
        field = np.vstack([pts.T, b.real.T, b.imag.T])
        if pad and len(pts):
            field = np.hstack([field, np.repeat(field[:, -1:], pad, axis=1)])
            field[3:, -pad:] = 0.0
        field_arr = wp.array(np.ascontiguousarray(field), dtype=wp.float64, device=dev)
        src = wp.array(np.ascontiguousarray(sources), dtype=wp.float64, device=dev)
        out = wp.zeros((po_derivative.ADJOINT_OUT, n), dtype=wp.float64, device=dev)
        table = wp.array(radiation.cis_table(), dtype=wp.vec2d, device=dev)
        step = 4 * (int(block or (2048 if dev == "cpu" else 16384)) // 4 or 1)
        for begin in range(0, field.shape[1], step):
            end = min(begin + step, field.shape[1])
            runtime.launch(po_derivative.adjoint_sum, n,
                           [field_arr, src, begin, end, elements.k, 1.0 / elements.k, table, out],
                           dev, min_chunk=16)
        acc = out.numpy()
    U = (acc[0:3] + 1j * acc[3:6]).T
    S = acc[6] + 1j * acc[7]
    elements.seconds["vjp"] = elements.seconds.get("vjp", 0.0) + time.perf_counter() - start
    g_z = np.real(np.sum(U * elements.dm_dz, axis=1) + S)
    g_x = np.real(np.sum(U * elements.dm_dhx, axis=1))
    g_y = np.real(np.sum(U * elements.dm_dhy, axis=1))
    return g_z, g_x, g_y
