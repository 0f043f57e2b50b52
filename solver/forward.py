"""Forward models of the refinement: a surface estimate on the aperture -> intensity on the sphere.

Frame and units (docs/physics.md): the estimate delta (m) on the aperture grid x, y (m), the sphere
grid (theta, phi in rad) of the scan, centred at the focus (0, 0, F); intensities relative to
the incident plane wave (dimensionless).

Every model needs only what a FieldMap carries: F, D, R and the grid, the probe that measured
it (:func:`raysim.maps.probe.probe_of`: its polarisation and pattern; a scan without probe
attributes was read by an ideal |E|^2 meter) and the incident polarisation (attribute
``polarization`` in rad; a scan without one was taken with E along x, docs/physics.md), and for
the wave models the frequency and whether the probe saw the scattered field alone or the total
field (attribute ``field``). Every model reads its field with the scan's probe, so the model's
intensity is the quantity the scan measured.
A FieldMap of a scene with obstacles carries their triangles (``obstacle_vertices``,
``obstacle_faces``): every model then puts the same obstacles in the beam (``obstacles``, a
:class:`raysim.surface.obstacles.ObstacleMesh`), so its ideal reflector casts the shadows the
data show.

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

Every model is a :class:`ForwardModel` and owns its caches: the ideal reflector's map (or
complex field) per scan geometry, kept for the model's life, so an inversion that passes one
model to several calls (``invert(..., forward=model)``) computes the ideal once; a fresh model
(the default of :func:`solver.invert.invert`) computes it once per inversion. A plain
function ``forward(sphere, F, D, x, y, delta)`` still works: :func:`as_model` wraps it.
Models report progress through ``progress(stage, fraction)`` (:mod:`raysim.progress`).

The wave models compute each field as a :class:`ForwardJob` of :mod:`raysim.distributed.blocks`:
in this process as one block, or, inside ``with distributed(runner):``, in blocks of sphere
points on a Dask cluster (:class:`raysim.distributed.BlockRunner`); the field is the same bit
for bit either way.
"""

from __future__ import annotations

import contextlib
import contextvars
import hashlib
from abc import ABC, abstractmethod
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from raysim.constants import wavenumber
from raysim.maps.probe import IDEAL, Probe, arrival_directions, probe_of
from raysim.maps.sphere import SphereGrid
from raysim.progress import Progress
from solver.errors import SolverError

MODELS = ("go", "po", "po+ptd", "go+edge")
WAVE_MODELS = ("po", "po+ptd", "go+edge")
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
    X band): GO stays the default there and ``model="po"`` or ``"go+edge"`` is the user's
    choice.
    """
    return method if method in MODELS else "go"


@dataclass
class GOForward(ForwardModel):
    """The project's GO engine (:class:`raysim.optics.go.ParaboloidTracer`): cell means of the
    ray-tube intensity, no diffraction. The model owns its tracer (the ideal mesh and BVH per
    geometry) and the ideal reflector's map per (sphere grid, F, D), for the model's life.
    ``probe`` reads the rays of the on-axis wave polarised at ``polarization`` (rad from x)."""

    device: str | None = "cpu"
    probe: Probe = IDEAL
    polarization: float = 0.0
    obstacles: Any = None  # ObstacleMesh in the beam, or None
    name = "go"
    _ideal: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    _tracer: Any = field(default=None, init=False, repr=False, compare=False)

    def __call__(self, sphere, F, D, x, y, delta, progress=None):
        if self._tracer is None:
            from raysim.optics.go import ParaboloidTracer

            self._tracer = ParaboloidTracer(self.device, obstacles=self.obstacles)
        if delta is None:
            key = (sphere, float(F), float(D))
            if key not in self._ideal:
                self._ideal[key] = self._tracer.intensity(sphere, float(F), float(D), None,
                                                          self.probe, self.polarization)
            return self._ideal[key].copy()
        from raysim.surface.gridded import GriddedMap

        return self._tracer.intensity(sphere, F, D, GriddedMap(x, y, delta), self.probe,
                                      self.polarization)

    def describe(self) -> str:
        return "raysim.optics.go GO engine (cell means, no diffraction)" + _probe_note(self.probe)


def go_forward(device: str | None = "cpu", obstacles: Any = None) -> GOForward:
    """The project's GO engine as the refinement's forward model (a new :class:`GOForward`),
    with ``obstacles`` (an ObstacleMesh) in the beam."""
    return GOForward(device, obstacles=obstacles)


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
    probe : what reads the field (:meth:`raysim.maps.probe.Probe.power`, the field taken to
        arrive on the probe's boresight, as the simulation's wave methods read it).
    obstacles : an :class:`raysim.surface.obstacles.ObstacleMesh` in the beam, or None.
    radiator, radiator_tol : the sum of the elements' fields (``fast``, the multilevel sum where
        it is cheaper, or ``direct``) and the fast sum's relative accuracy
        (:func:`raysim.optics.fast.radiator.make_radiator`); the model's fields and its
        Jacobian's products (:class:`solver.jacobian.WaveJacobian`) both use them.
    """

    frequency_hz: float
    polarization: float = 0.0
    total: bool = False
    ptd: bool = False
    samples_per_wavelength: float | None = None
    face_m: float = PO_FACE_M
    device: str | None = "cpu"
    probe: Probe = IDEAL
    obstacles: Any = None
    radiator: str = "fast"
    radiator_tol: float = 1e-6
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
                f"{'default' if spw is None else f'{spw:g}'} samples per wavelength"
                f"{_probe_note(self.probe)}")

    def __call__(self, sphere: SphereGrid, F: float, D: float, x: NDArray, y: NDArray,
                 delta: NDArray | None, progress: Progress | None = None) -> NDArray:
        if delta is None:
            return self.read(sphere, self.ideal_field(sphere, F, D, progress))
        E = self._field(sphere, F, D, (np.asarray(x), np.asarray(y), np.asarray(delta)), progress)
        return self.read(sphere, E)

    def read(self, sphere: SphereGrid, E: NDArray[np.complex128]) -> NDArray[np.float64]:
        """What the model's probe reads (n_theta, n_phi) of the field E (n_theta, n_phi, 3)."""
        if self.probe.ideal:
            return np.sum(np.abs(E) ** 2, axis=-1)
        return self.probe.power(E, arrival_directions(sphere.directions()))

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

    def field(self, sphere: SphereGrid, F: float, D: float, surface: tuple | None,
              progress: Progress | None = None) -> NDArray[np.complex128]:
        """Complex E (n_theta, n_phi, 3) of the paraboloid plus ``surface`` ((x, y, delta) grids
        in m, delta finite everywhere; None: the ideal reflector), the field this model's
        intensity is |E|^2 of (not cached)."""
        return self._field(sphere, F, D, surface, progress)

    def reflector(self, D: float, F: float, surface: tuple | None):
        """The reflector this model radiates: its :meth:`paraboloid` plus ``surface``
        (:func:`deformed`)."""
        return deformed(self.paraboloid(D, F), surface)

    def paraboloid(self, D: float, F: float):
        """The smooth ideal paraboloid on the model's quadrature faces, built once per dish."""
        key = (float(D), float(F))
        if key not in self._meshes:
            from raysim.surface.mesh import paraboloid

            self._meshes[key] = paraboloid(key[0], key[1], float(self.face_m)).with_obstacles(
                self.obstacles)
        return self._meshes[key]

    def wavenumber(self) -> float:
        """k = 2 pi f / c (rad/m)."""
        return wavenumber(self.frequency_hz)

    def _field(self, sphere: SphereGrid, F: float, D: float, surface: tuple | None,
               progress: Progress | None) -> NDArray[np.complex128]:
        """E (n_theta, n_phi, 3) of the paraboloid plus ``surface`` (x, y, delta grids; None:
        the ideal one), in this process or on the runner of :func:`distributed`."""
        import time

        from raysim.optics import po

        start = time.perf_counter()
        wave = self.job(sphere, F, D, surface).wave()
        E = self._scattered(sphere, F, D, surface, wave, progress)
        if self.total:
            points = sphere.points(F)
            E = E + po.incident_field(points.reshape(-1, 3), wave.k, wave.k_hat,
                                      wave.e_hat).reshape(E.shape)
        self.calls += 1
        self.seconds += time.perf_counter() - start
        return E

    def _scattered(self, sphere: SphereGrid, F: float, D: float, surface: tuple | None, wave,
                   progress: Progress | None) -> NDArray[np.complex128]:
        """The scattered field (n_theta, n_phi, 3): PO, with PTD's rim, as a block job (in this
        process or on the runner of :func:`distributed`)."""
        from raysim.optics.radiator import field_of

        job = self.job(sphere, F, D, surface)
        runner = _RUNNER.get()
        if runner is None:
            context = job.build(self.device or "cpu", False, self.paraboloid(D, F))
            arrays, _ = context.evaluate(0, job.n_points, progress)
        else:
            arrays = runner.evaluate(job, progress)
        shape = (sphere.n_theta, sphere.n_phi, 3)
        E = field_of({"electric": arrays["po"]}, wave.k).reshape(shape)
        if self.ptd:
            E = E + field_of({"fringe": arrays["edges"]}, wave.k).reshape(shape)
        return E

    def job(self, sphere: SphereGrid, F: float, D: float, surface: tuple | None) -> ForwardJob:
        """This model's field of the paraboloid (D, F in m) plus ``surface`` as a block job."""
        spw = self.samples_per_wavelength
        job = ForwardJob("", float(D), float(F), float(self.face_m), float(self.frequency_hz),
                         float(self.polarization), spw, self.ptd, sphere, str(self.device or "cpu"),
                         surface, obstacles=self.obstacles, radiator=self.radiator,
                         radiator_tol=float(self.radiator_tol))
        return replace(job, key=job.fingerprint())


def deformed(ideal: Any, surface: tuple | None) -> Any:
    """The reflector ``ideal`` moved by the gridded map ``surface`` ((x, y, delta) grids in m,
    :class:`raysim.surface.gridded.GriddedMap`; None: ``ideal`` itself): what every wave model
    radiates, and what :class:`solver.jacobian.WaveJacobian` linearises."""
    if surface is None:
        return ideal
    from raysim.surface.gridded import GriddedMap

    return ideal.deformed(GriddedMap(*surface))


_RUNNER: contextvars.ContextVar[Any] = contextvars.ContextVar("raysim_forward_runner", default=None)


@dataclass
class GOEdgeForward(WaveForward):
    """The go+edge engine (:mod:`raysim.optics.goedge`) in place of PO: the geometric wave of
    the paraboloid plus a gridded delta (ray tubes on the ``face_m`` mesh, subdivided to the
    engine's ray spacing) and the diffraction of its rim, at the cell centres. It runs in
    this process (seconds per field): a Dask runner is not used."""

    # the geometric wave answers to fine shapes as GO does: no Fresnel smoothing to undo
    fresnel_smoothing = False

    @property
    def name(self) -> str:
        return "go+edge"

    def describe(self) -> str:
        return (f"raysim.optics.goedge (geometric wave + rim diffraction) at "
                f"{self.frequency_hz / 1e9:g} GHz, E at {np.degrees(self.polarization):g} deg from x, "
                f"{'total' if self.total else 'scattered'} field, {self.face_m:g} m faces"
                f"{_probe_note(self.probe)}")

    def _scattered(self, sphere: SphereGrid, F: float, D: float, surface: tuple | None, wave,
                   progress: Progress | None) -> NDArray[np.complex128]:
        from raysim.optics import goedge

        return goedge.sphere_field(self.reflector(D, F, surface), sphere, wave,
                                   device=self.device).E


def active_runner() -> Any:
    """The runner of the enclosing :func:`distributed` block (None outside one)."""
    return _RUNNER.get()


@contextlib.contextmanager
def distributed(runner: Any) -> Iterator[None]:
    """Inside the block, the wave models compute their fields on ``runner`` (an object with
    ``evaluate(job, progress) -> arrays``, such as :class:`raysim.distributed.BlockRunner`)."""
    token = _RUNNER.set(runner)
    try:
        yield
    finally:
        _RUNNER.reset(token)


@dataclass(frozen=True)
class ForwardJob:
    """One wave-model field as a job of :mod:`raysim.distributed.blocks`: the paraboloid
    (D, F in m) on ``face_m`` quadrature faces plus ``surface`` (x, y, delta grids in m; None
    for the ideal), under the on-axis plane wave, at the cell centres of ``sphere``."""

    key: str
    D: float
    F: float
    face_m: float
    frequency_hz: float
    polarization: float
    samples_per_wavelength: float | None
    ptd: bool
    sphere: SphereGrid
    device: str
    surface: tuple | None
    threads: int = 1
    obstacles: Any = None
    radiator: str = "fast"
    radiator_tol: float = 1e-6

    @property
    def n_points(self) -> int:
        return self.sphere.n_theta * self.sphere.n_phi

    def fingerprint(self) -> str:
        h = hashlib.sha256(repr((self.D, self.F, self.face_m, self.frequency_hz, self.polarization,
                                 self.samples_per_wavelength, self.ptd, self.sphere,
                                 self.device, self.radiator, self.radiator_tol)).encode())
        if self.obstacles is not None:
            h.update(self.obstacles.digest().encode())
        for grid in self.surface or ():
            h.update(np.ascontiguousarray(grid, dtype=np.float64).tobytes())
        return h.hexdigest()

    def parts(self) -> dict[str, tuple[int, ...]]:
        return {"po": (6,), "edges": (6,)} if self.ptd else {"po": (6,)}

    def wave(self) -> Any:
        from raysim.optics.illumination import Illumination

        e_hat = (np.cos(self.polarization), np.sin(self.polarization), 0.0)
        return Illumination.plane_wave(self.frequency_hz, (0.0, 0.0, -1.0), e_hat)

    def build(self, device: str, keep: bool, ideal: Any = None) -> _ForwardContext:
        """The job's elements in this process; ``ideal``: the paraboloid on the job's faces
        when the caller keeps it (a model's own), else built here."""
        from raysim.optics import po
        from raysim.optics.sources import Sources
        from raysim.surface.mesh import paraboloid
        from raysim.surface.quadrature import targets_around

        reflector = deformed(ideal if ideal is not None else
                             paraboloid(self.D, self.F, self.face_m).with_obstacles(self.obstacles),
                             self.surface)
        spw = po.DEFAULT_SAMPLES_PER_WAVELENGTH if self.samples_per_wavelength is None \
            else self.samples_per_wavelength
        from raysim.optics.fast.chart import domain_of

        points = self.sphere.points(self.F).reshape(-1, 3)
        wave = self.wave()
        sources = Sources(reflector, wave, spw, "rim" if self.ptd else None, device, keep,
                          radiator=self.radiator, tol=self.radiator_tol,
                          targets=targets_around(points, (0.0, 0.0, self.F), wave.k_hat))
        # the whole grid's chart domain: every block is summed on the same grids (same bits)
        return _ForwardContext(sources, points, domain_of(points, (0.0, 0.0, self.F)))


class _ForwardContext:
    """A forward job's elements in one process (:class:`raysim.simulate.BlockContext`)."""

    def __init__(self, sources, points: NDArray[np.float64], domain: Any = None) -> None:
        self.sources, self.points, self.domain = sources, points, domain

    def evaluate(self, lo: int, hi: int, progress: Progress | None = None):
        out = self.sources.radiate(self.points[lo:hi], progress, domain=self.domain)
        arrays = {"po": out.sums["electric"]}
        if "fringe" in out.sums:
            arrays["edges"] = out.sums["fringe"]
        return arrays, {"pairs": float(out.pairs), "seconds": out.seconds}

    def attrs(self) -> dict[str, Any]:
        self.sources.prime()
        return {"engine": {"samples": int(self.sources.stats.n_samples)}}

    def digest(self) -> str:
        return self.sources.digest()



def forward_for(model: str, attrs: dict, device: str | None = "cpu",
                samples_per_wavelength: float | None = None,
                obstacles: Any = None, radiator: str = "fast",
                radiator_tol: float = 1e-6) -> tuple[ForwardModel, str]:
    """The forward model named ``model`` for a scan with FieldMap attributes ``attrs`` and
    ``obstacles`` (the scan's ObstacleMesh, or None) in the beam; ``radiator``,
    ``radiator_tol``: the PO / PO + PTD models' sum (:class:`WaveForward`).

    Returns the model and a one-line description for the SurfaceMap.
    """
    if model not in MODELS:
        raise SolverError(f"unknown model {model!r}: choose one of {', '.join(MODELS)}")
    probe = probe_of(attrs)
    polarization = float(attrs.get("polarization", 0.0))
    if model == "go":
        go = GOForward(device, probe, polarization, obstacles)
        return go, go.describe() + _with_obstacles(obstacles)
    frequency = float(attrs.get("frequency_hz", 0.0))
    if not frequency > 0:
        raise SolverError(f"model {model} needs the scan's frequency_hz (> 0), got {frequency}")
    from raysim.errors import RaysimError
    from raysim.simulate import check_wave_size

    try:  # the engines' memory, before any work: the cap simulate has
        check_wave_size(model, float(attrs.get("diameter", 0.0)), frequency, samples_per_wavelength)
    except RaysimError as exc:
        raise SolverError(str(exc)) from exc
    kind = GOEdgeForward if model == "go+edge" else WaveForward
    wave = kind(frequency, polarization,
                total=str(attrs.get("field", "scattered")) == "total",
                ptd=model == "po+ptd", samples_per_wavelength=samples_per_wavelength,
                device=device, probe=probe, obstacles=obstacles, radiator=radiator,
                radiator_tol=radiator_tol)
    return wave, wave.describe() + _with_obstacles(obstacles)


def _probe_note(probe: Probe) -> str:
    """The model description's probe clause (nothing for the ideal |E|^2 meter)."""
    return "" if probe.ideal else f", read by the scan's probe ({probe.describe()})"


def _with_obstacles(obstacles: Any) -> str:
    """The words a model's description gets for its obstacles."""
    return "" if obstacles is None else f", with the scan's obstacles ({obstacles.description})"
