"""Physical optics: PO surface currents on the reflector radiated to the probe sphere.

Frame and units of docs/physics.md (reflector frame, metres, SI fields); time convention
exp(+j w t). The incident plane wave is E_inc = e_hat exp(-j k k_hat . r) (unit amplitude, V/m),
H_inc = (k_hat x E_inc) / eta. On the lit part of the reflector (samples the wave reaches:
Warp's BVH tests each one) the PO current is J = 2 n x H_inc, n the unit normal on the side
the wave comes from (Balanis, *Advanced Engineering Electromagnetics*, 2nd ed., sec. 7.10).
It radiates through the full free-space dyadic Green's function, all of the 1/(kR),
1/(kR)^2 and 1/(kR)^3 terms (the probe sphere is in the near field of the dish): see
:mod:`raysim.optics.kernels.po`. The surface integral is a quadrature on the mesh faces,
lifted onto the smooth surface where the scene has one (:mod:`raysim.surface.quadrature`).

What other engines share lives beside it: the incident wave (:mod:`raysim.optics.illumination`),
the radiator of current elements (:mod:`raysim.optics.radiator`) and the shadow test
(:mod:`raysim.optics.bvh`). Here: :func:`po_elements` gives a reflector's PO current elements
chunk by chunk; :func:`scatter` and :func:`sphere_field` radiate them. Fields add: an
edge-current engine radiates its own elements through a Radiator on the same points.

Sampling: ``samples_per_wavelength`` Gauss points per free-space wavelength along every face
edge (:mod:`raysim.surface.quadrature`). Near the focus the reflector's integrand varies about three
times slower than the free-space wavelength, so the default of 1.5 on faces of several
wavelengths (``scenes/paper_po.toml``) converges the paper case to about 1e-8; field points
close to a surface and far from its focus (the disk test) need 3 to 4.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.maps.sphere import SphereGrid
from raysim.optics import runtime
from raysim.optics.bvh import ReflectorBVH, facet_sag, shadow_tolerance
from raysim.optics.fast.chart import Domain
from raysim.optics.fast.radiator import DEFAULT_TOL, make_radiator
from raysim.optics.illumination import C0, ETA0, MU0, Illumination, Taper, incident_field
from raysim.optics.radiator import CurrentElements, Radiator
from raysim.optics.shadow_edge import lit_samples
from raysim.progress import Progress
from raysim.surface.mesh import Reflector
from raysim.surface.quadrature import FaceQuadrature, plan

# names other modules and users reach through this one (the PO engine's vocabulary)
__all__ = ["C0", "DEFAULT_SAMPLES_PER_WAVELENGTH", "ETA0", "MU0", "CurrentElements", "ElementStats",
           "Illumination", "POResult", "Radiator", "Taper", "facet_sag", "incident_field", "po_elements",
           "scatter", "shadow_tolerance", "sphere_field"]

DEFAULT_SAMPLES_PER_WAVELENGTH = 1.5


@dataclass
class ElementStats:
    """Counts gathered while making PO elements (updated chunk by chunk)."""

    n_samples: int = 0
    n_lit: int = 0


def po_elements(reflector: Reflector, wave: Illumination, quadrature: FaceQuadrature,
                device: str = "cpu", taper: Taper | None = None, stats: ElementStats | None = None,
                chunk: int = 262_144, bvh: ReflectorBVH | None = None) -> Iterator:
    """PO current elements of ``reflector`` under ``wave``, chunk by chunk.

    Yields Warp (9, N) float64 arrays on ``device`` in the :class:`Radiator` layout (electric
    elements J dA, A m). Samples the BVH finds shadowed carry no current and are left out, and
    a face a shadow's edge crosses is integrated over its lit part (:mod:`raysim.optics.shadow_edge`);
    ``taper(x, y)`` (optional, dimensionless) multiplies each sample's current. The lit side
    of each sample is its face's side towards the wave: the samples' vector areas point to the
    dish's front times a quadrature weight that can be negative (the circular segments cut
    from a panel at a concave ring edge), so their own direction does not tell it. ``bvh``:
    the reflector's BVH when the caller already has it (built here otherwise).
    """
    from raysim.optics.kernels import po as po_kernels

    wp = runtime.init()
    dev = runtime.resolve_device(device)
    stats = stats if stats is not None else ElementStats()
    bvh = bvh if bvh is not None else ReflectorBVH.build(reflector, dev)
    h_hat = wave.h_hat
    v = reflector.vertices[reflector.faces]
    back_lit = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]) @ wave.k_hat > 0.0  # wave meets the back
    for samples in quadrature.chunks(chunk):
        # the lit samples, the faces a shadow's edge crosses cut along it (shadow_edge)
        lit, n = lit_samples(quadrature, samples, bvh, wave.k_hat)
        area = np.where(back_lit[lit.face][:, None], -lit.area, lit.area)
        points = lit.points
        if taper is not None:
            area = area * np.asarray(taper(points[:, 0], points[:, 1]), dtype=np.float64)[:, None]
        stats.n_samples += n
        stats.n_lit += len(lit)
        m = len(points)
        if m == 0:
            continue
        src = wp.zeros((9, m), dtype=wp.float64, device=dev)
        runtime.launch(po_kernels.po_currents, m,
                            [wp.array(points, dtype=wp.vec3d, device=dev),
                             wp.array(area, dtype=wp.vec3d, device=dev),
                             wp.vec3d(*wave.k_hat), wp.vec3d(*h_hat), wave.k, ETA0, src], dev)
        yield src


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
            progress: Progress | None = None, radiator: str = "direct", tol: float = DEFAULT_TOL,
            centre: ArrayLike | None = None, domain: Domain | None = None) -> POResult:
    """PO field scattered by ``reflector`` at ``points`` (n, 3), m, reflector frame.

    ``samples_per_wavelength`` sets the quadrature (samples about lambda / that apart);
    ``taper(x, y)`` optionally weights the current (1 inside, smoothly to 0, for tests);
    ``radiator``, ``tol``, ``centre``, ``domain``: as :func:`raysim.optics.fast.radiator.make_radiator`.
    """
    start = time.perf_counter()
    report = progress or (lambda stage, fraction: None)
    dev = runtime.resolve_device(device)
    quadrature = plan(reflector, wave.wavelength, samples_per_wavelength)
    total = max(quadrature.n_samples, 1)
    rad = make_radiator(points, wave.k, dev, radiator=radiator, tol=tol, centre=centre, domain=domain)
    stats = ElementStats()
    done = 0
    report("currents", 0.0)
    for src in po_elements(reflector, wave, quadrature, dev, taper, stats):
        base = done

        def sub(stage: str, f: float, base: int = base, size: int = src.shape[1]) -> None:
            report(f"radiating, {stage}", min(1.0, (base + f * size) / total))

        rad.add_packed(src, progress=sub)
        done = stats.n_samples
    return POResult(rad.field(), stats.n_samples, stats.n_lit, rad.pairs,
                    time.perf_counter() - start, rad.seconds)


def sphere_field(reflector: Reflector, grid: SphereGrid, wave: Illumination,
                 samples_per_wavelength: float = DEFAULT_SAMPLES_PER_WAVELENGTH,
                 device: str | None = "cpu", taper: Taper | None = None,
                 progress: Progress | None = None, radiator: str = "direct",
                 tol: float = DEFAULT_TOL) -> POResult:
    """PO scattered field at the cell centres of ``grid`` (sphere about the focus (0, 0, F)).

    ``E`` has shape (n_theta, n_phi, 3); ``radiator`` ``fast`` or ``direct`` (``tol``: fast's).
    """
    points = grid.points(reflector.F).reshape(-1, 3)
    result = scatter(reflector, points, wave, samples_per_wavelength, device, taper, progress,
                     radiator, tol, centre=(0.0, 0.0, float(reflector.F)))
    return POResult(result.E.reshape(grid.n_theta, grid.n_phi, 3), result.n_samples, result.n_lit,
                    result.pairs, result.seconds, result.seconds_radiate)
