"""Physical optics: PO surface currents on the reflector radiated to the probe sphere.

Frame and units of DESIGN.md (reflector frame, metres, SI fields); time convention
exp(+j w t). The incident plane wave is E_inc = e_hat exp(-j k k_hat . r) (unit amplitude, V/m),
H_inc = (k_hat x E_inc) / eta. On the lit part of the reflector (samples the wave reaches:
Warp's BVH tests each one) the PO current is J = 2 n x H_inc, n the unit normal on the side
the wave comes from (Balanis, *Advanced Engineering Electromagnetics*, 2nd ed., sec. 7.10).
It radiates through the full free-space dyadic Green's function, all of the 1/(kR),
1/(kR)^2 and 1/(kR)^3 terms (the probe sphere is in the near field of the dish): see
:mod:`raysim.optics.kernels.po`. The surface integral is a quadrature on the mesh faces,
lifted onto the smooth surface where the scene has one (:mod:`raysim.surface.quadrature`).

The pieces other engines (PTD edge currents) build on: :class:`Radiator` accumulates the
field of any electric or magnetic current elements (:class:`CurrentElements`: I dl or J dA in
A m, K dl or M dA in V m) at fixed field points, in float64, split over the field points on the
CPU's threads; :class:`Illumination` is the incident wave and :func:`incident_field` its E;
:func:`po_elements` gives a reflector's PO current elements chunk by chunk; :func:`scatter`
and :func:`sphere_field` put them together. Fields add: an edge-current engine radiates its
own elements through a Radiator on the same points and adds the result to ``scatter``'s.

Sampling: ``samples_per_wavelength`` Gauss points per free-space wavelength along every face
edge (:mod:`raysim.surface.quadrature`). Near the focus the reflector's integrand varies about three
times slower than the free-space wavelength, so the default of 1.5 on faces of several
wavelengths (``scenes/paper_po.toml``) converges the paper case to about 1e-8; field points
close to a surface and far from its focus (the disk test) need 3 to 4.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.errors import RaysimError
from raysim.maps.sphere import SphereGrid
from raysim.optics import runtime as warp_runtime
from raysim.surface.mesh import Reflector
from raysim.surface.quadrature import FaceQuadrature, plan

C0 = 299_792_458.0  # speed of light in vacuum (m/s)
MU0 = 1.25663706212e-6  # vacuum permeability (H/m), CODATA 2018
ETA0 = MU0 * C0  # free-space impedance (Ohm), about 376.73
DEFAULT_SAMPLES_PER_WAVELENGTH = 1.5
Progress = Callable[[str, float], None]
Taper = Callable[[NDArray, NDArray], NDArray]


@dataclass(frozen=True)
class CurrentElements:
    """Point current elements (reflector frame).

    ``positions`` (N, 3) in m; ``moments`` (N, 3) complex: J dA or I dl in A m for electric
    elements, M dA or K dl in V m for magnetic ones (``magnetic`` True).
    """

    positions: NDArray[np.float64]
    moments: NDArray[np.complex128]
    magnetic: bool = False

    def __len__(self) -> int:
        return len(self.positions)

    def packed(self) -> NDArray[np.float64]:
        """The (9, N) float64 layout of the kernels: position, Re moment, Im moment."""
        m = np.asarray(self.moments, dtype=np.complex128)
        return np.ascontiguousarray(np.vstack([np.asarray(self.positions, dtype=np.float64).T,
                                               m.real.T, m.imag.T]))


class Radiator:
    """The field (V/m) of current elements at fixed points, accumulated in float64.

    Parameters
    ----------
    points : (n, 3) field points (m, reflector frame).
    k : wavenumber (rad/m).
    device : Warp device (``cpu``, ``cuda``, ``cuda:N``).
    block : elements per launch (a cache-sized block on the CPU; each field point sums a
        block in registers, then adds it to its total: a two-level sum).
    tile : field points per kernel thread for electric elements: 4 on the CPU (each element
        is loaded once for four points), 1 on CUDA; None picks by device.
    """

    def __init__(self, points: ArrayLike, k: float, device: str | None = "cpu",
                 block: int | None = None, tile: int | None = None) -> None:
        from raysim.optics.kernels import po as K

        self.wp = warp_runtime.init()
        self.device = warp_runtime.resolve_device(device)
        self.K = K
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        self.n = len(pts)
        self.k = float(k)
        self.cpu = self.device == "cpu"
        self.tile = int(tile or (4 if self.cpu else 1))
        if self.tile not in (1, 4):
            raise RaysimError(f"tile must be 1 or 4, got {self.tile}")
        # the four-point kernel needs a multiple of four points: pad with copies of the last
        n_pad = -(-self.n // self.tile) * self.tile
        padded = np.vstack([pts, np.repeat(pts[-1:], n_pad - self.n, axis=0)])
        wp = self.wp
        self.field_points = wp.array(np.ascontiguousarray(padded.T), dtype=wp.float64, device=self.device)
        self.E_electric = wp.zeros((6, n_pad), dtype=wp.float64, device=self.device)
        self.E_magnetic = wp.zeros((6, n_pad), dtype=wp.float64, device=self.device)
        self.table = wp.array(K.cis_table(), dtype=wp.vec2d, device=self.device)
        self.block = int(block or (2048 if self.cpu else 16384))
        self.pairs = 0
        self.seconds = 0.0
        self._bounds = (pts.min(axis=0), pts.max(axis=0))

    def add(self, elements: CurrentElements, progress: Progress | None = None) -> None:
        """Add the field of ``elements`` at every point."""
        if len(elements) == 0:
            return
        src = self.wp.array(elements.packed(), dtype=self.wp.float64, device=self.device)
        self.add_packed(src, magnetic=elements.magnetic, progress=progress)

    def add_packed(self, src, magnetic: bool = False, progress: Progress | None = None) -> None:
        """Add elements already on the device in the (9, N) layout (a Warp float64 array)."""
        n_src = src.shape[1]
        if n_src == 0:
            return
        self._check_phase(src)
        K = self.K
        if magnetic:
            kernel, out, tile = K.radiate_magnetic, self.E_magnetic, 1
        elif self.tile == 4:
            kernel, out, tile = K.radiate_electric4, self.E_electric, 4
        else:
            kernel, out, tile = K.radiate_electric, self.E_electric, 1
        dim = self.field_points.shape[1] // tile
        for begin in range(0, n_src, self.block):
            end = min(begin + self.block, n_src)
            start = time.perf_counter()
            warp_runtime.launch(kernel, dim, [self.field_points, src, begin, end, self.k,
                                              1.0 / self.k, self.table, out],
                                self.device, min_chunk=16)
            self.seconds += time.perf_counter() - start
            self.pairs += (end - begin) * self.n
            if progress is not None:
                progress(f"{self.rate() / 1e6:.0f} M pairs/s", end / n_src)

    def _check_phase(self, src) -> None:
        """The kernels' phase reduction holds for kR < MAX_PHASE: refuse anything beyond."""
        pos = src.numpy()[:3]
        lo = np.minimum(pos.min(axis=1), self._bounds[0])
        hi = np.maximum(pos.max(axis=1), self._bounds[1])
        reach = float(np.linalg.norm(hi - lo))  # bounds any element-to-point distance (m)
        if self.k * reach >= self.K.MAX_PHASE:
            raise RaysimError(f"k R up to {self.k * reach:.3g} rad exceeds the kernel's phase "
                              f"range {self.K.MAX_PHASE:.3g} rad: lower the frequency")

    def rate(self) -> float:
        """Pairs (element x field point) per second so far."""
        return self.pairs / self.seconds if self.seconds > 0 else 0.0

    def field(self) -> NDArray[np.complex128]:
        """E (n, 3) complex (V/m) of everything added so far."""
        e = self.E_electric.numpy()[:, : self.n]
        m = self.E_magnetic.numpy()[:, : self.n]
        sum_e = (e[:3] + 1j * e[3:]).T
        sum_m = (m[:3] + 1j * m[3:]).T
        return (-1j * self.k * ETA0 / (4.0 * np.pi)) * sum_e + (1j * self.k / (4.0 * np.pi)) * sum_m


def incident_field(points: ArrayLike, k: float, k_hat: ArrayLike, e_hat: ArrayLike) -> NDArray:
    """E_inc = e_hat exp(-j k k_hat . r) at ``points`` (n, 3) in m: (n, 3) complex, V/m."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    phase = np.exp(-1j * k * (pts @ np.asarray(k_hat, dtype=np.float64)))
    return phase[:, None] * np.asarray(e_hat, dtype=np.float64)[None, :]


@dataclass(frozen=True)
class Illumination:
    """The incident plane wave: wavenumber k (rad/m), unit propagation k_hat, unit E e_hat."""

    k: float
    k_hat: NDArray[np.float64]
    e_hat: NDArray[np.float64]

    @classmethod
    def plane_wave(cls, frequency_hz: float, k_hat: ArrayLike, e_hat: ArrayLike) -> Illumination:
        kh = np.asarray(k_hat, dtype=np.float64)
        kh = kh / np.linalg.norm(kh)
        eh = np.asarray(e_hat, dtype=np.float64)
        eh = eh - (eh @ kh) * kh
        return cls(2.0 * np.pi * frequency_hz / C0, kh, eh / np.linalg.norm(eh))

    @property
    def wavelength(self) -> float:
        return 2.0 * np.pi / self.k


@dataclass
class ElementStats:
    """Counts gathered while making PO elements (updated chunk by chunk)."""

    n_samples: int = 0
    n_lit: int = 0


def po_elements(reflector: Reflector, wave: Illumination, quadrature: FaceQuadrature,
                device: str = "cpu", taper: Taper | None = None, stats: ElementStats | None = None,
                chunk: int = 262_144) -> Iterator:
    """PO current elements of ``reflector`` under ``wave``, chunk by chunk.

    Yields Warp (9, N) float64 arrays on ``device`` in the :class:`Radiator` layout (electric
    elements J dA, A m). Samples the BVH finds shadowed carry no current and are left out;
    ``taper(x, y)`` (optional, dimensionless) multiplies each sample's current. The lit side
    of each sample is its face's side towards the wave: the samples' vector areas point to the
    dish's front times a quadrature weight that can be negative (the circular segments cut
    from a panel at a concave ring edge), so their own direction does not tell it.
    """
    from raysim.optics.kernels import po as po_kernels

    wp = warp_runtime.init()
    dev = warp_runtime.resolve_device(device)
    stats = stats if stats is not None else ElementStats()
    mesh = wp.Mesh(points=wp.array(reflector.vertices.astype(np.float32), dtype=wp.vec3, device=dev),
                   indices=wp.array(reflector.faces.astype(np.int32).ravel(), dtype=wp.int32, device=dev))
    standoff = float(np.ptp(reflector.vertices, axis=0).max() + 10.0)
    tolerance = shadow_tolerance(reflector)
    h_hat = np.cross(wave.k_hat, wave.e_hat)
    v = reflector.vertices[reflector.faces]
    back_lit = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]) @ wave.k_hat > 0.0  # wave meets the back
    for samples in quadrature.chunks(chunk):
        n = len(samples)
        lit = wp.zeros(n, dtype=wp.int32, device=dev)
        warp_runtime.launch(po_kernels.lit_samples, n,
                            [mesh.id, wp.array(samples.facet, dtype=wp.vec3d, device=dev),
                             wp.array(samples.face.astype(np.int32), dtype=wp.int32, device=dev),
                             wp.vec3d(*wave.k_hat), standoff, tolerance, lit], dev)
        keep = lit.numpy().astype(bool)
        area = np.where(back_lit[samples.face[keep]][:, None], -samples.area[keep], samples.area[keep])
        points = samples.points[keep]
        if taper is not None:
            area = area * np.asarray(taper(points[:, 0], points[:, 1]), dtype=np.float64)[:, None]
        stats.n_samples += n
        stats.n_lit += int(keep.sum())
        m = len(points)
        if m == 0:
            continue
        src = wp.zeros((9, m), dtype=wp.float64, device=dev)
        warp_runtime.launch(po_kernels.po_currents, m,
                            [wp.array(points, dtype=wp.vec3d, device=dev),
                             wp.array(area, dtype=wp.vec3d, device=dev),
                             wp.vec3d(*wave.k_hat), wp.vec3d(*h_hat), wave.k, ETA0, src], dev)
        yield src


def facet_sag(reflector: Reflector) -> float:
    """Largest distance (m) along z between a face's flat facet and the smooth surface, at the
    face centroids (0 for a mesh without a smooth surface)."""
    if reflector.surface is None or len(reflector.faces) == 0:
        return 0.0
    c = reflector.vertices[reflector.faces].mean(axis=1)
    panel = reflector.face_panel if reflector.layout is not None else None
    return float(np.abs(reflector.surface.height(c[:, 0], c[:, 1], panel) - c[:, 2]).max())


def shadow_tolerance(reflector: Reflector) -> float:
    """How far (m) before a point another face may meet its ray without shadowing it: 1 mm
    plus twice the facets' sag. At a panel's edge the neighbouring panel's facet, a chord of
    the surface like its own, can overlap it in projection by that much without hiding it."""
    return 1e-3 + 2.0 * facet_sag(reflector)


@dataclass(frozen=True)
class POResult:
    """Scattered field of one reflector: ``E`` (n, 3) complex, V/m for the unit incident wave."""

    E: NDArray[np.complex128]
    n_samples: int
    n_lit: int
    pairs: int
    seconds: float
    seconds_radiate: float

    @property
    def pair_rate(self) -> float:
        return self.pairs / self.seconds_radiate if self.seconds_radiate > 0 else 0.0


def scatter(reflector: Reflector, points: ArrayLike, wave: Illumination,
            samples_per_wavelength: float = DEFAULT_SAMPLES_PER_WAVELENGTH,
            device: str | None = "cpu", taper: Taper | None = None,
            progress: Progress | None = None) -> POResult:
    """PO field scattered by ``reflector`` at ``points`` (n, 3), m, reflector frame.

    ``samples_per_wavelength`` sets the quadrature (samples about lambda / that apart);
    ``taper(x, y)`` optionally weights the current (1 inside, smoothly to 0, for tests).
    """
    start = time.perf_counter()
    report = progress or (lambda stage, fraction: None)
    dev = warp_runtime.resolve_device(device)
    quadrature = plan(reflector, wave.wavelength, samples_per_wavelength)
    total = max(quadrature.n_samples, 1)
    radiator = Radiator(points, wave.k, dev)
    stats = ElementStats()
    done = 0
    report("currents", 0.0)
    for src in po_elements(reflector, wave, quadrature, dev, taper, stats):
        base = done

        def sub(stage: str, f: float, base: int = base, size: int = src.shape[1]) -> None:
            report(f"radiating, {stage}", min(1.0, (base + f * size) / total))

        radiator.add_packed(src, progress=sub)
        done = stats.n_samples
    return POResult(radiator.field(), stats.n_samples, stats.n_lit, radiator.pairs,
                    time.perf_counter() - start, radiator.seconds)


def sphere_field(reflector: Reflector, grid: SphereGrid, wave: Illumination,
                 samples_per_wavelength: float = DEFAULT_SAMPLES_PER_WAVELENGTH,
                 device: str | None = "cpu", taper: Taper | None = None,
                 progress: Progress | None = None) -> POResult:
    """PO scattered field at the cell centres of ``grid`` (sphere about the focus (0, 0, F)).

    ``E`` has shape (n_theta, n_phi, 3).
    """
    points = grid.points(reflector.F).reshape(-1, 3)
    result = scatter(reflector, points, wave, samples_per_wavelength, device, taper, progress)
    return POResult(result.E.reshape(grid.n_theta, grid.n_phi, 3), result.n_samples, result.n_lit,
                    result.pairs, result.seconds, result.seconds_radiate)
