"""Forward models of the refinement: a surface estimate on the aperture -> intensity on the sphere.

Frame and units (docs/physics.md): the estimate delta (m) on the aperture grid x, y (m), the sphere
grid (theta, phi in rad) of the scan, centred at the focus (0, 0, F); intensities relative to
the incident plane wave (dimensionless).

Every model needs only what a FieldMap carries: F, D, R and the grid, and for the wave models
the frequency, the incident polarisation (attribute ``polarization`` in rad; a scan without
one was taken with E along x, docs/physics.md) and whether the probe saw the scattered field alone
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

Every model is a :class:`ForwardModel` and owns its caches: the ideal reflector's map (or
complex field) per scan geometry, kept for the model's life, so an inversion that passes one
model to several calls (``invert(..., forward=model)``) computes the ideal once; a fresh model
(the default of :func:`solver.invert.invert`) computes it once per inversion. A plain
function ``forward(sphere, F, D, x, y, delta)`` still works: :func:`as_model` wraps it.
Models report progress through ``progress(stage, fraction)`` (:mod:`raysim.progress`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from raysim.constants import wavenumber
from raysim.maps.sphere import SphereGrid
from raysim.progress import Progress
from solver.errors import SolverError

MODELS = ("go", "po", "po+ptd")
WAVE_MODELS = ("po", "po+ptd")
PO_FACE_M = 5.0      # quadrature face size of the PO model (m): large faces, high-order rules
IDEAL_CACHE_SIZE = 4

# forward(sphere, F, D, x, y, delta) -> intensity (n_theta, n_phi); delta None for the ideal
# reflector, else (N, N) in m on the aperture grid x, y (finite everywhere).
Forward = Callable[[SphereGrid, float, float, NDArray, NDArray, NDArray | None], NDArray]


class ForwardModel(ABC):
    """A forward model of the refinement: the intensity on the sphere of a surface estimate.

    Calling it with (sphere, F, D, x, y, delta) returns the intensity (n_theta, n_phi) of the
    paraboloid of focal length F and diameter D (m) plus ``delta`` (m, (N, N) on the aperture
    grid x, y, finite everywhere), or of the ideal reflector for ``delta`` None; ``progress``
    (optional) follows the call. ``name`` says what physics it is (go, po, po+ptd, or the
    caller's word) and :meth:`describe` says it in a line for the SurfaceMap.
    """

    name: str = "caller"

    @abstractmethod
    def __call__(self, sphere: SphereGrid, F: float, D: float, x: NDArray, y: NDArray,
                 delta: NDArray | None, progress: Progress | None = None) -> NDArray: ...

    def describe(self) -> str:
        return f"caller's ({self.name})"


class WaveModel(ForwardModel):
    """A wave-optics model: also gives the ideal reflector's complex field, which the wave
    preconditioner (:class:`solver.wave.WaveCorrection`) is built from."""

    frequency_hz: float
    polarization: float

    @abstractmethod
    def ideal_field(self, sphere: SphereGrid, F: float, D: float,
                    progress: Progress | None = None) -> NDArray[np.complex128]: ...


@dataclass(frozen=True)
class CallableModel(ForwardModel):
    """A plain function ``forward(sphere, F, D, x, y, delta)`` as a model (no progress)."""

    function: Forward
    name: str = "caller"

    def __call__(self, sphere, F, D, x, y, delta, progress=None):
        return self.function(sphere, F, D, x, y, delta)


def as_model(forward: ForwardModel | Forward) -> ForwardModel:
    """``forward`` as a :class:`ForwardModel` (a plain function is wrapped)."""
    return forward if isinstance(forward, ForwardModel) else CallableModel(forward)


def model_for_method(method: str) -> str:
    """The default model for data of ``method``: like for like; GO for measured scans.

    A measured scan is wave physics, but the PO cost grows with f^2 (hours per call at
    X band): GO stays the default there and ``model="po"`` is the user's choice.
    """
    return method if method in MODELS else "go"


@dataclass
class GOForward(ForwardModel):
    """The project's GO engine (:func:`raysim.optics.go.forward_intensity`): cell means of the
    ray-tube intensity, no diffraction. The ideal reflector's map depends only on (sphere
    grid, F, D) and is kept per geometry for the model's life (the engine keeps its mesh)."""

    device: str | None = "cpu"
    name = "go"
    _ideal: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __call__(self, sphere, F, D, x, y, delta, progress=None):
        from raysim.optics.go import forward_intensity

        if delta is None:
            key = (sphere, float(F), float(D))
            if key not in self._ideal:
                self._ideal[key] = forward_intensity(sphere, float(F), float(D), None, device=self.device)
            return self._ideal[key].copy()
        from raysim.surface.gridded import GriddedMap

        return forward_intensity(sphere, F, D, GriddedMap(x, y, delta), device=self.device)

    def describe(self) -> str:
        return "raysim.optics.go GO engine (cell means, no diffraction)"


def go_forward(device: str | None = "cpu") -> GOForward:
    """The project's GO engine as the refinement's forward model (a new :class:`GOForward`)."""
    return GOForward(device)


@dataclass
class WaveForward(WaveModel):
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
    _ideal: OrderedDict = field(default_factory=OrderedDict, init=False, repr=False, compare=False)
    _meshes: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def name(self) -> str:
        return "po+ptd" if self.ptd else "po"

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
        from raysim.surface.gridded import GriddedMap

        E = self._field(sphere, F, D, GriddedMap(x, y, delta), progress)
        return np.sum(np.abs(E) ** 2, axis=-1)

    def ideal_field(self, sphere: SphereGrid, F: float, D: float,
                    progress: Progress | None = None) -> NDArray[np.complex128]:
        """Complex E (n_theta, n_phi, 3) of the ideal reflector (V/m per V/m incident), kept
        per scan geometry (the last :data:`IDEAL_CACHE_SIZE`)."""
        key = (sphere, float(F), float(D))
        if key not in self._ideal:
            self._ideal[key] = self._field(sphere, F, D, None, progress)
            while len(self._ideal) > IDEAL_CACHE_SIZE:
                self._ideal.popitem(last=False)
        return self._ideal[key].copy()

    def paraboloid(self, D: float, F: float):
        """The smooth ideal paraboloid on the model's quadrature faces, built once per dish."""
        key = (float(D), float(F))
        if key not in self._meshes:
            from raysim.surface.mesh import paraboloid

            self._meshes[key] = paraboloid(key[0], key[1], float(self.face_m))
        return self._meshes[key]

    def wavenumber(self) -> float:
        """k = 2 pi f / c (rad/m)."""
        return wavenumber(self.frequency_hz)

    def _field(self, sphere: SphereGrid, F: float, D: float, deformation,
               progress: Progress | None) -> NDArray[np.complex128]:
        import time

        from raysim.optics import po

        start = time.perf_counter()
        ideal = self.paraboloid(D, F)
        reflector = ideal if deformation is None else ideal.deformed(deformation)
        e_hat = (np.cos(self.polarization), np.sin(self.polarization), 0.0)
        wave = po.Illumination.plane_wave(self.frequency_hz, (0.0, 0.0, -1.0), e_hat)
        spw = po.DEFAULT_SAMPLES_PER_WAVELENGTH if self.samples_per_wavelength is None \
            else self.samples_per_wavelength
        E = po.sphere_field(reflector, sphere, wave, spw, self.device, progress=progress).E
        if self.ptd:
            E = E + _ptd_field(reflector, sphere, wave, self.device)
        if self.total:
            points = sphere.points(F)
            E = E + po.incident_field(points.reshape(-1, 3), wave.k, wave.k_hat,
                                      wave.e_hat).reshape(E.shape)
        self.calls += 1
        self.seconds += time.perf_counter() - start
        return E


def _ptd_field(reflector, sphere: SphereGrid, wave, device) -> NDArray[np.complex128]:
    """The PTD fringe field (n_theta, n_phi, 3) of the reflector's rim, from :mod:`raysim.optics.ptd`."""
    from raysim.optics import ptd

    return ptd.sphere_edge_field(reflector, sphere, wave, "rim", device=device).E


def forward_for(model: str, attrs: dict, device: str | None = "cpu",
                samples_per_wavelength: float | None = None) -> tuple[ForwardModel, str]:
    """The forward model named ``model`` for a scan with FieldMap attributes ``attrs``.

    Returns the model and a one-line description for the SurfaceMap.
    """
    if model not in MODELS:
        raise SolverError(f"unknown model {model!r}: choose one of {', '.join(MODELS)}")
    if model == "go":
        go = GOForward(device)
        return go, go.describe()
    frequency = float(attrs.get("frequency_hz", 0.0))
    if not frequency > 0:
        raise SolverError(f"model {model} needs the scan's frequency_hz (> 0), got {frequency}")
    wave = WaveForward(frequency, float(attrs.get("polarization", 0.0)),
                       total=str(attrs.get("field", "scattered")) == "total",
                       ptd=model == "po+ptd", samples_per_wavelength=samples_per_wavelength,
                       device=device)
    return wave, wave.describe()
