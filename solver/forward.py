"""Forward models of the refinement: a surface estimate on the aperture -> intensity on the sphere.

Frame and units (DESIGN.md): the estimate delta (m) on the aperture grid x, y (m), the sphere
grid (theta, phi in rad) of the scan, centred at the focus (0, 0, F); intensities relative to
the incident plane wave (dimensionless).

Every model needs only what a FieldMap carries: F, D, R and the grid, and for the wave models
the frequency, the incident polarisation (attribute ``polarization`` in rad; a scan without
one was taken with E along x, DESIGN.md) and whether the probe saw the scattered field alone
or the total field (attribute ``field``).

- ``go``: the project's GO engine (:func:`raysim.optics.go.forward_intensity`): cell means, no
  diffraction. Cheap (a second or two per call on the paper grid).
- ``po``: the project's PO engine (:func:`raysim.optics.po.sphere_field`): the field of the PO
  currents of the smooth surface z = r^2/(4F) + delta, integrated on large faces (5 m, like
  ``scenes/paper_po.toml``) with the engine's own sampling rule, at the cell centres. It
  carries the wave effects GO lacks: edge-diffraction rings, the smoothing of the response to
  features of a few wavelengths. Its cost grows with f^2 (about 45 s per call at 0.3 GHz on
  the paper grid on two idle cores).
- ``po+ptd``: PO plus the fringe field of the rim from :mod:`raysim.optics.ptd` (a few per cent of
  PO's cost).
- ``go+edge``: the geometric wave of ray tubes plus the diffraction of the rim from
  :mod:`raysim.optics.goedge`: PO + PTD's physics to leading order in 1/k (closer as the
  frequency rises) at a cost that grows only linearly with f (seconds per call on the paper
  grid at 1 to 3 GHz, where a PO call takes tens of minutes).

The ideal reflector's field is computed once per (model, scan geometry) and kept for the
session. A model object reports its progress through ``progress(stage, fraction)`` when the
refinement passes one (``reports_progress``).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from raysim.maps.sphere import SphereGrid
from solver.errors import SolverError

MODELS = ("go", "po", "po+ptd", "go+edge")
WAVE_MODELS = ("po", "po+ptd", "go+edge")
PO_FACE_M = 5.0      # quadrature face size of the PO model (m): large faces, high-order rules
IDEAL_CACHE_SIZE = 4

# forward(sphere, F, D, x, y, delta) -> intensity (n_theta, n_phi); delta None for the ideal
# reflector, else (N, N) in m on the aperture grid x, y (finite everywhere).
Forward = Callable[[SphereGrid, float, float, NDArray, NDArray, NDArray | None], NDArray]
Progress = Callable[[str, float], None]


def model_for_method(method: str) -> str:
    """The default model for data of ``method``: like for like; GO for measured scans.

    A measured scan is wave physics, but the PO cost grows with f^2 (hours per call at
    X band): GO stays the default there and ``model="po"`` or ``"go+edge"`` is the user's
    choice.
    """
    return method if method in MODELS else "go"


def go_forward(device: str | None = "cpu") -> Forward:
    """The project's GO engine as the refinement's forward model (imported on first use).

    The ideal reflector's map depends only on (sphere grid, F, D, device) and is kept for the
    session, so repeated inversions of one scan geometry trace it once.
    """

    def forward(sphere, F, D, x, y, delta):
        if delta is None:
            return _ideal_go(sphere, float(F), float(D), device).copy()
        from raysim.optics.go import forward_intensity
        from raysim.surface.deformation import GriddedMap

        return forward_intensity(sphere, F, D, GriddedMap(x, y, delta), device=device)

    return forward


@lru_cache(maxsize=IDEAL_CACHE_SIZE)
def _ideal_go(sphere: SphereGrid, F: float, D: float, device: str | None) -> NDArray:
    from raysim.optics.go import forward_intensity

    return forward_intensity(sphere, F, D, None, device=device)


@dataclass
class WaveForward:
    """PO (optionally + PTD) intensity of the paraboloid plus a gridded delta, at cell centres.

    Parameters
    ----------
    frequency_hz : frequency of the incident plane wave (Hz), on axis (travelling along -z).
    polarization : angle of E from x about the axis (rad): E = (cos, sin, 0).
    total : True when the probe saw the scattered plus the incident field, else scattered.
    ptd : add the rim's PTD fringe field (:mod:`raysim.optics.ptd`).
    samples_per_wavelength : PO quadrature (None: the engine's default).
    face_m : quadrature face size (m).
    device : Warp device.
    """

    frequency_hz: float
    polarization: float = 0.0
    total: bool = False
    ptd: bool = False
    samples_per_wavelength: float | None = None
    face_m: float = PO_FACE_M
    device: str | None = "cpu"
    calls: int = field(default=0, compare=False)
    seconds: float = field(default=0.0, compare=False)
    reports_progress = True

    @property
    def name(self) -> str:
        return "po+ptd" if self.ptd else "po"

    def key(self) -> tuple:
        """What the ideal field depends on besides the scan geometry."""
        return (self.name, float(self.frequency_hz), float(self.polarization), self.total,
                self.samples_per_wavelength, float(self.face_m), self.device)

    def describe(self) -> str:
        spw = self.samples_per_wavelength
        return (f"raysim.optics.po {'+ raysim.optics.ptd ' if self.ptd else ''}at "
                f"{self.frequency_hz / 1e9:g} GHz, E at {np.degrees(self.polarization):g} deg "
                f"from x, {'total' if self.total else 'scattered'} field, {self.face_m:g} m faces, "
                f"{'default' if spw is None else f'{spw:g}'} samples per wavelength")

    def __call__(self, sphere: SphereGrid, F: float, D: float, x: NDArray, y: NDArray,
                 delta: NDArray | None, progress: Progress | None = None) -> NDArray:
        if delta is None:
            return np.sum(np.abs(self.ideal_field(sphere, F, D, progress)) ** 2, axis=-1)
        from raysim.surface.deformation import GriddedMap

        E = self._field(sphere, F, D, GriddedMap(x, y, delta), progress)
        return np.sum(np.abs(E) ** 2, axis=-1)

    def ideal_field(self, sphere: SphereGrid, F: float, D: float,
                    progress: Progress | None = None) -> NDArray[np.complex128]:
        """Complex E (n_theta, n_phi, 3) of the ideal reflector (V/m per V/m incident), cached."""
        key = (self.key(), sphere, float(F), float(D))
        if key not in _IDEAL_WAVE:
            _IDEAL_WAVE[key] = self._field(sphere, F, D, None, progress)
            while len(_IDEAL_WAVE) > IDEAL_CACHE_SIZE:
                _IDEAL_WAVE.popitem(last=False)
        return _IDEAL_WAVE[key].copy()

    def wavenumber(self) -> float:
        """k = 2 pi f / c (rad/m)."""
        from raysim.optics.po import C0

        return 2.0 * np.pi * self.frequency_hz / C0

    def _field(self, sphere: SphereGrid, F: float, D: float, deformation,
               progress: Progress | None) -> NDArray[np.complex128]:
        import time

        from raysim.optics import po

        start = time.perf_counter()
        ideal = _paraboloid(float(D), float(F), float(self.face_m))
        reflector = ideal if deformation is None else ideal.deformed(deformation)
        e_hat = (np.cos(self.polarization), np.sin(self.polarization), 0.0)
        wave = po.Illumination.plane_wave(self.frequency_hz, (0.0, 0.0, -1.0), e_hat)
        E = self._scattered(reflector, sphere, wave, progress)
        if self.total:
            points = sphere.points(F)
            E = E + po.incident_field(points.reshape(-1, 3), wave.k, wave.k_hat,
                                      wave.e_hat).reshape(E.shape)
        self.calls += 1
        self.seconds += time.perf_counter() - start
        return E

    def _scattered(self, reflector, sphere: SphereGrid, wave,
                   progress: Progress | None) -> NDArray[np.complex128]:
        """The scattered field (n_theta, n_phi, 3) of ``reflector``: PO, with PTD's rim."""
        from raysim.optics import po

        spw = po.DEFAULT_SAMPLES_PER_WAVELENGTH if self.samples_per_wavelength is None \
            else self.samples_per_wavelength
        E = po.sphere_field(reflector, sphere, wave, spw, self.device, progress=progress).E
        if self.ptd:
            E = E + _ptd_field(reflector, sphere, wave, self.device)
        return E


_IDEAL_WAVE: OrderedDict[tuple, NDArray[np.complex128]] = OrderedDict()


@dataclass
class GOEdgeForward(WaveForward):
    """The go+edge engine (:mod:`raysim.optics.goedge`) in place of PO: the geometric wave of
    the paraboloid plus a gridded delta (ray tubes on the ``face_m`` mesh, subdivided to the
    engine's ray spacing) and the diffraction of its rim, at the cell centres."""

    # the geometric wave answers to fine shapes as GO does: no Fresnel smoothing to undo
    fresnel_smoothing = False

    @property
    def name(self) -> str:
        return "go+edge"

    def describe(self) -> str:
        return (f"raysim.optics.goedge (geometric wave + rim diffraction) at "
                f"{self.frequency_hz / 1e9:g} GHz, E at {np.degrees(self.polarization):g} deg from x, "
                f"{'total' if self.total else 'scattered'} field, {self.face_m:g} m faces")

    def _scattered(self, reflector, sphere: SphereGrid, wave,
                   progress: Progress | None) -> NDArray[np.complex128]:
        from raysim.optics import goedge

        return goedge.sphere_field(reflector, sphere, wave, device=self.device).E


@lru_cache(maxsize=4)
def _paraboloid(D: float, F: float, face_m: float):
    from raysim.surface.mesh import paraboloid

    return paraboloid(D, F, face_m)


def _ptd_field(reflector, sphere: SphereGrid, wave, device) -> NDArray[np.complex128]:
    """The PTD fringe field (n_theta, n_phi, 3) of the reflector's rim, from :mod:`raysim.optics.ptd`."""
    from raysim.optics import ptd

    return ptd.sphere_edge_field(reflector, sphere, wave, "rim", device=device).E


def forward_for(model: str, attrs: dict, device: str | None = "cpu",
                samples_per_wavelength: float | None = None) -> tuple[Forward, str]:
    """The forward model named ``model`` for a scan with FieldMap attributes ``attrs``.

    Returns the model and a one-line description for the SurfaceMap.
    """
    if model not in MODELS:
        raise SolverError(f"unknown model {model!r}: choose one of {', '.join(MODELS)}")
    if model == "go":
        return go_forward(device), "raysim.optics.go GO engine (cell means, no diffraction)"
    frequency = float(attrs.get("frequency_hz", 0.0))
    if not frequency > 0:
        raise SolverError(f"model {model} needs the scan's frequency_hz (> 0), got {frequency}")
    kind = GOEdgeForward if model == "go+edge" else WaveForward
    wave = kind(frequency, float(attrs.get("polarization", 0.0)),
                total=str(attrs.get("field", "scattered")) == "total",
                ptd=model == "po+ptd", samples_per_wavelength=samples_per_wavelength,
                device=device)
    return wave, wave.describe()
