"""Scene -> FieldMap: build the ideal and deformed reflectors, run an engine on both.

``simulate(scene)`` is the library's main entry point (the ``raysim simulate`` command is a
thin layer over it). The FieldMap it returns carries both intensities, the scene's TOML text
and the run's figures (rays, power balance, times) as flat attributes.

Each method is one engine function in :data:`ENGINES`, ``(scene, ideal, deformed, options,
device, progress) -> Run``: the two intensities on the scene's sphere grid, how they are sampled
(GO cell means, wave-optics cell centres) and the engine's own attributes and variables. What
every method shares (the reflectors, the scene's attributes, the FieldMap) is done once here.

Methods whose field at a sphere point does not depend on the other points (every wave engine)
are also a :class:`BlockEngine` in :data:`BLOCK_ENGINES`: a per-process context evaluates any
block of the grid's points on its own, and a finishing step turns the whole grid's arrays into
the Run. A single process evaluates one block, the whole grid; :mod:`raysim.distributed`
evaluates many on Dask workers, and the FieldMap is the same bit for bit (each point's values
come from the same sums in the same order, and the finishing step is the same code on the same
arrays).
"""

from __future__ import annotations

import math
import os
import sys
import threading
import time
import types
from collections.abc import Callable
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from raysim.errors import RaysimError, SceneError
from raysim.maps.fieldmap import fieldmap
from raysim.maps.sphere import theta_rim
from raysim.methods import METHODS, WAVE_METHODS
from raysim.optics import go, runtime
from raysim.optics.fast import DEFAULT_TOL
from raysim.progress import Progress
from raysim.scene import Scene
from raysim.surface.mesh import Reflector, mesh_departure_rms, reflectors_for

if TYPE_CHECKING:
    from raysim.optics.sources import Sources

#: the peak memory of a wave run (PO + PTD, ideal and deformed, fast radiator) is bounded by
#: WAVE_BASE_BYTES + BYTES_PER_PO_SAMPLE x the PO source samples held at once + BYTES_PER_SAMPLE_KEPT
#: x the PO source samples of one reflector. The fast radiator holds at most a batch of elements
#: (raysim.optics.fast.radiator.BATCH_BYTES, 72 bytes each): the walk holds its chunks of grids
#: (a bounded few GB) beside the batch's elements in leaf order and their order (80 bytes a
#: sample), the tree's planning about 135 bytes a sample at its peak
#: (benchmarks/bench_plan_memory.py: 133 at 6 GHz, 127 at 12 GHz). Every batch's tree is kept
#: for the deformed reflector (its order, 8 bytes a sample, and its clusters). Measured whole
#: runs on the paper's dish (benchmarks/bench_wave_cost.py, peak RSS): 1.1 GB at 0.3 GHz, 2.2 GB
#: at 1 GHz, 2.8 GB at 3 GHz (7.5 M samples; the model says 3.7), 4.8 GB at 6 GHz (28.7 M; the
#: model says 7.0), 5.7 GB at 12 GHz (112.5 M, four batches; the model says 8.5); the direct sum
#: holds less
WAVE_BASE_BYTES = 2.5e9
BYTES_PER_PO_SAMPLE = 140.0
BYTES_PER_SAMPLE_KEPT = 16.0
#: PO samples per spacing^2 of surface: the face quadrature (raysim.surface.quadrature) puts
#: n^2 points on a face whose longest edge is n spacings, 4 per spacing^2 on a mesh of right
#: triangles (the paper's dish: 3.8 at 0.3 GHz, 3.4 at 6 GHz, 4.7 at 0.1 GHz where faces
#: take the rule's least order)
SAMPLES_PER_SPACING2 = 4.0


def physical_memory() -> float:
    """This machine's physical memory (bytes); infinite where the system does not say (no
    sysconf, or the -1 it gives for a value it does not know)."""
    try:
        page, pages = os.sysconf("SC_PAGE_SIZE"), os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return math.inf
    return float(page * pages) if page > 0 and pages > 0 else math.inf


def batch_samples() -> float:
    """The PO source samples a batch of the fast radiator holds at most (its
    :data:`~raysim.optics.fast.radiator.BATCH_BYTES` of elements, 72 bytes each)."""
    from raysim.optics.fast.radiator import BATCH_BYTES
    from raysim.optics.sources import BYTES_PER_ELEMENT

    return BATCH_BYTES / BYTES_PER_ELEMENT


def wave_bytes(samples: float) -> float:
    """The most memory (bytes) a wave run takes with ``samples`` PO source samples per
    reflector: :data:`WAVE_BASE_BYTES` + :data:`BYTES_PER_PO_SAMPLE` x the samples of a batch
    (:func:`batch_samples`, or all of them when fewer) + :data:`BYTES_PER_SAMPLE_KEPT` x
    ``samples``."""
    held = min(samples, batch_samples())
    return WAVE_BASE_BYTES + BYTES_PER_PO_SAMPLE * held + BYTES_PER_SAMPLE_KEPT * samples


def max_po_samples() -> float:
    """The most PO source samples per reflector a wave run may take here: as many as
    :func:`wave_bytes` fits in this machine's memory (about 1.2e9 on 25 GB)."""
    room = max(physical_memory() - WAVE_BASE_BYTES, 0.0)
    batch = batch_samples()
    if room <= (BYTES_PER_PO_SAMPLE + BYTES_PER_SAMPLE_KEPT) * batch:
        return room / (BYTES_PER_PO_SAMPLE + BYTES_PER_SAMPLE_KEPT)
    return (room - BYTES_PER_PO_SAMPLE * batch) / BYTES_PER_SAMPLE_KEPT


@dataclass(frozen=True)
class Options:
    """Engine options beyond the scene (see :func:`simulate`)."""

    total: bool = False
    save_field: bool = False
    samples_per_wavelength: float | None = None
    edges: str | None = None
    fresnel: bool = False
    radiator: str = "fast"
    radiator_tol: float = DEFAULT_TOL


@dataclass
class Run:
    """What an engine hands back: intensities (n_theta, n_phi) relative to the incident wave."""

    intensity: NDArray[np.float64]
    intensity_ideal: NDArray[np.float64]
    sampling: str  # "cell_mean" or "centre" (the FieldMap contract)
    attrs: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)  # further FieldMap variables
    coords: dict = field(default_factory=dict)
    blocked_share: NDArray[np.float64] | None = None  # GO engine with obstacles: the ideal's


Engine = Callable[[Scene, Reflector, Reflector, Options, str | None, Progress], Run]


def scene_attrs(scene: Scene, deformed: Reflector, ideal: Reflector) -> dict:
    """The FieldMap attributes that describe the scene and its mesh, whatever the method; for a
    mesh file, also ``mesh_departure_rms_m``: its RMS departure along z from its ideal (the
    ``ideal_mesh``, else the fitted paraboloid), which a file not in the reflector frame
    inflates (an axis tilted by 0.05 deg reads as 0.46 mm on a 25 m dish); and
    ``scene_folder``, where the files the scene names resolve (absolute)."""
    mesh = ({} if scene.dish.mesh is None else {"mesh_departure_rms_m": mesh_departure_rms(ideal, deformed)})
    folder = {} if scene.path is None else {"scene_folder": str(Path(scene.path).resolve().parent)}
    return {
        **mesh, **folder,
        "scene_name": scene.name,
        "deformation": scene.deformation.describe(),
        "incidence_theta": scene.source.incidence_theta,
        "incidence_phi": scene.source.incidence_phi,
        "polarization": scene.source.polarization,
        "mesh_resolution": ideal_resolution(scene),
        "mesh_faces": len(deformed.faces),
        "panels": int(deformed.n_panels),
        **scene.probe.attrs(),  # none for the ideal |E|^2 meter (raysim.maps.probe)
    }


def simulate(scene: Scene, method: str | None = None, device: str | None = "cpu",
             progress: Progress | None = None, *, total: bool = False, save_field: bool = False,
             samples_per_wavelength: float | None = None, edges: str | None = None,
             fresnel: bool = False, radiator: str = "fast", radiator_tol: float = DEFAULT_TOL) -> xr.Dataset:
    """Simulate ``scene`` and return its FieldMap (an ``xarray.Dataset``; see raysim.maps.fieldmap).

    Parameters
    ----------
    scene : a validated scene (``raysim.load_scene``).
    method : ``go`` (geometric optics), ``po`` (physical optics), ``po+ptd`` (PO plus the
        fringe field of the edges, :mod:`raysim.optics.ptd`) or ``go+edge`` (the geometric wave
        plus every free edge's diffraction, :mod:`raysim.optics.goedge`: wave optics at a cost
        that does not grow as f^2); None takes the scene's ``method``.
    device : ``cpu`` or ``cuda`` (Warp device).
    progress : optional callback (stage name, fraction done in 0..1).
    total : wave methods only: intensity of the total field (scattered plus incident) at the
        probe, instead of the scattered field alone.
    save_field : wave methods only: also store the complex field components (V/m per V/m
        incident).
    samples_per_wavelength : PO only: Gauss points per wavelength along the mesh faces'
        edges (default :data:`raysim.optics.po.DEFAULT_SAMPLES_PER_WAVELENGTH`).
    edges : ``po+ptd`` only: ``rim`` (the outer rim, the paper's PTD; the default) or ``all``
        (the rim and every panel edge beside a gap).
    fresnel : ``go+edge`` only: add the deformed geometric wave's Fresnel-zone correction
        (:mod:`raysim.optics.fresnel`), for deformations with structure finer than the Fresnel
        zone (on the paper's dish, below about 3 GHz).
    radiator : ``po``/``po+ptd`` only: ``fast`` (the multilevel sum of
        :mod:`raysim.optics.fast`, where its cost estimate beats the direct sum's) or ``direct``
        (the reference sum); ``radiator_tol`` the fast sum's relative accuracy. The FieldMap
        records ``radiator``, ``radiator_ran`` (what summed each kind of element) and, with
        ``fast``, ``radiator_tol``.
    """
    options = Options(total, save_field, samples_per_wavelength, edges, fresnel, radiator, radiator_tol)
    method = check_method(scene, method, options, device)
    report = progress or (lambda stage, fraction: None)
    start = time.perf_counter()
    report("mesh", 0.0)
    ideal, deformed = reflectors_for(scene)
    mesh_seconds = time.perf_counter() - start
    run = ENGINES[method](scene, ideal, deformed, options, device, report)
    run = with_blockage(ideal, run, scene.sphere, scene.source.direction, device)
    report("done", 1.0)
    attrs = {**scene_attrs(scene, deformed, ideal), **run.attrs, "device": str(device or "cpu"),
             "seconds_mesh": mesh_seconds, "seconds_total": time.perf_counter() - start}
    return fieldmap_of(scene, method, run, deformed.F, deformed.D, attrs)


def po_samples(diameter: float, frequency_hz: float,
               samples_per_wavelength: float | None = None) -> float:
    """PO's source samples on one reflector of diameter ``diameter`` (m) at ``frequency_hz``
    (Hz) with ``s`` samples per wavelength, before any mesh exists:
    :data:`SAMPLES_PER_SPACING2` pi (D/2)^2 / (lambda/s)^2."""
    from raysim.constants import wavelength
    from raysim.optics.po import DEFAULT_SAMPLES_PER_WAVELENGTH

    spw = samples_per_wavelength or DEFAULT_SAMPLES_PER_WAVELENGTH
    return SAMPLES_PER_SPACING2 * math.pi * (diameter / 2) ** 2 / (wavelength(frequency_hz) / spw) ** 2


def check_wave_size(method: str, diameter: float, frequency_hz: float,
                    samples_per_wavelength: float | None = None) -> None:
    """Refuse a wave computation whose memory would not fit, before any work (RaysimError,
    one line): its size is PO's source samples per reflector (:func:`po_samples`), at most
    :func:`max_po_samples` (the one cap of simulate, datasets and the inversion's wave
    models)."""
    samples = po_samples(diameter, frequency_hz, samples_per_wavelength)
    if not samples <= max_po_samples():
        raise RaysimError(f"{method} at {frequency_hz:g} Hz needs about {samples:.2g} source samples "
                          f"per reflector, about {wave_bytes(samples) / 1e9:.2g} GB, more "
                          f"than this machine's {physical_memory() / 1e9:.3g} GB: use go, or a "
                          "lower frequency")


def check_method(scene: Scene, method: str | None, options: Options,
                 device: str | None = None) -> str:
    """The method to run (``method``, else the scene's), its options and ``device`` (when
    given) checked before any work; raises RaysimError with one line."""
    if not isinstance(scene, Scene):  # a path failed deep in the mesh code
        raise SceneError(f"simulate takes a Scene (raysim.load_scene(path) reads one), not "
                          f"{type(scene).__name__}")
    method = scene.method if method is None else method
    if method not in ENGINES:
        raise RaysimError(f"unknown method {method!r}: use one of {', '.join(METHODS)}")
    _check_options(method, options)
    if method in ("po", "po+ptd") and scene.dish.diameter is not None:
        check_wave_size(method, scene.D, scene.source.frequency_hz, options.samples_per_wavelength)
    if device is not None:
        from raysim.optics.runtime import resolve_device

        resolve_device(device)
    return method


def check_options(scene: Scene, *, method: str | None = None, device: str | None = "cpu",
                  total: bool = False, save_field: bool = False,
                  samples_per_wavelength: float | None = None, edges: str | None = None,
                  fresnel: bool = False, radiator: str = "fast", radiator_tol: float = DEFAULT_TOL) -> str:
    """Refuse what :func:`simulate` cannot honour, before any work (the keywords of
    :func:`simulate`); return the method that would run."""
    return check_method(scene, method, Options(total, save_field, samples_per_wavelength, edges, fresnel,
                                               radiator, radiator_tol), device)


def fieldmap_of(scene: Scene, method: str, run: Run, F: float, D: float, attrs: dict) -> xr.Dataset:
    """The FieldMap of ``run`` on the scene's grid (F, D of the reflector in m; flat attrs)."""
    ideal = np.asarray(run.intensity_ideal)
    if method == "go" and not np.any(np.isfinite(ideal) & (ideal > 0)):
        # all the rays missed the grid (off-axis incidence of 30 deg on a hemisphere): the
        # FieldMap's own check said "no ideal intensity", which does not say why
        raise RaysimError(f"no GO ray of the ideal dish reached the sphere's cells (incidence "
                          f"{math.degrees(math.acos(-float(scene.source.direction[2]))):.3g} deg "
                          "from the axis, the grid's theta and phi ranges): widen the grid or "
                          "tilt the incidence less")
    ds = fieldmap(scene.sphere, run.intensity, run.intensity_ideal, focal_length=F, diameter=D,
                  frequency_hz=scene.source.frequency_hz, method=method, sampling=run.sampling,
                  scene=scene.text, attrs=attrs, extra=run.extra)
    return ds.assign_coords(run.coords) if run.coords else ds


def with_blockage(ideal: Reflector, run: Run, grid, direction, device: str | None) -> Run:
    """``run`` with the obstacles' FieldMap variables and attributes
    (:func:`raysim.optics.blockage.fieldmap_variables`) when ``ideal`` has obstacles: the
    blocked share of the GO engine's own ideal trace, or of a GO trace of ``ideal`` made here
    for the wave engines (their FieldMaps mark the cells GO rays cannot reach)."""
    if ideal.obstacles is None:
        return run
    from raysim.optics import blockage, blocked_cells

    share = run.blocked_share
    if share is None:
        share = blocked_cells.ideal_blocked_share(ideal, grid, direction, device)
    extra, attrs = blockage.fieldmap_variables(share, ideal.obstacles)
    run.extra = {**run.extra, **extra}
    run.attrs = {**run.attrs, **attrs}
    return run


def _check_options(method: str, options: Options) -> None:
    """Refuse options that do not apply to ``method`` (one line for the user)."""
    from raysim.optics.fast.radiator import RADIATORS, tol_problem

    if options.edges is not None and method != "po+ptd":
        raise RaysimError("--edges applies to --method po+ptd only")
    if options.edges is not None and options.edges not in ("rim", "all"):
        raise RaysimError(f"unknown edge set {options.edges!r}: use rim or all")
    if method not in WAVE_METHODS and (options.total or options.save_field):
        # go+edge is a wave method too: it takes these two (not the quadrature's density)
        raise RaysimError(f"--total and --save-field apply to the wave methods "
                          f"({', '.join(WAVE_METHODS)}), not {method}")
    if method not in WAVE_METHODS and options.samples_per_wavelength is not None:
        raise RaysimError("--samples-per-wavelength applies to --method po and po+ptd only")
    if options.fresnel and method != "go+edge":
        raise RaysimError("--fresnel applies to --method go+edge only")
    if method == "go+edge" and options.samples_per_wavelength is not None:
        raise RaysimError("--samples-per-wavelength applies to --method po and po+ptd only")
    if options.radiator not in RADIATORS:
        raise RaysimError(f"unknown radiator {options.radiator!r}: use fast or direct")
    if (problem := tol_problem(options.radiator_tol, "--radiator-tol")) is not None:
        raise RaysimError(problem)
    spw = options.samples_per_wavelength
    if spw is not None and not (math.isfinite(spw) and 0 < spw <= 20):
        raise RaysimError(f"--samples-per-wavelength must lie in (0, 20], got {spw:g}")


def _stage(report: Progress, offset: float, width: float, label: str) -> Progress:
    """A sub-progress for one reflector: its fractions mapped onto offset..offset + width."""
    return lambda name, f: report(f"{label}: {name}", offset + width * f)


#: lattice points (rays) at most that the automatic GO lattice of a mesh file asks for
MAX_AUTO_RAYS = 20_000_000


def go_subdivisions(scene: Scene, reflector: Reflector) -> tuple[int, str]:
    """(m, note): the GO rays per face edge for ``scene``'s ``reflector`` and, when chosen
    here, how. A scene's ``[go] subdivisions`` is taken as stated; a generated dish's
    triangles are ``dish.resolution`` already (m = 1). A mesh file's faces are whatever its
    author exported (a CAD panel is often two triangles): with rays at its vertices only, each
    tube spreads its power evenly over a footprint metres wide: 5 % RMS (20 % at worst) off
    the ideal intensity on a 12 m dish of triangles up to 3.4 m, where rays 0.15 m apart (the
    generated dish's
    triangle, :data:`raysim.scene.scene.DEFAULT_RESOLUTION`; ``scene.ray_spacing`` where set)
    give 0.02 % (tests/raysim/surface/test_mesh_lattice.py). So the lattice puts rays that far
    apart on the faces' edges (the 95th percentile of their longest; at most 16 per edge and
    :data:`MAX_AUTO_RAYS` rays; the note warns where the longest faces keep rays more than
    twice that far apart)."""
    from raysim.scene.scene import DEFAULT_RESOLUTION

    if scene.subdivisions is not None:
        return int(scene.subdivisions), ""
    if scene.dish.mesh is None:
        return 1, ""
    spacing = scene.ray_spacing or DEFAULT_RESOLUTION
    v = reflector.vertices[reflector.faces]
    edges = np.linalg.norm(v - np.roll(v, 1, axis=1), axis=2).max(axis=1)  # each face's longest
    if not len(edges):
        return 1, ""
    # the faces' 95th percentile, not the longest: a few long chords at the rim and the
    # panels' edges would double every face's rays for nothing. A generated dish's triangle of
    # edge ``spacing`` is a right triangle, its longest edge sqrt(2) times that: a mesh as fine
    # keeps its rays at the vertices, as the generated dish does
    wanted = max(1, math.ceil(float(np.percentile(edges, 95)) / (math.sqrt(2.0) * spacing) - 1e-9))
    if wanted == 1:
        return 1, ""
    m = 1
    while m < min(wanted, 16) and (m + 2) * (m + 3) // 2 * len(edges) <= MAX_AUTO_RAYS:
        m += 1
    longest = float(edges.max())
    note = f"GO rays {m} per face edge of the mesh (its longest edge {longest:.3g} m)"
    if longest / m > 2.0 * math.sqrt(2.0) * spacing:
        note += (f"; WARNING: rays {longest / m:.3g} m apart on its longest faces, whose GO tubes "
                 "spread their power evenly over that width: refine the mesh there")
    return m, note


def _run_go(scene: Scene, ideal: Reflector, deformed: Reflector, options: Options,
            device: str | None, report: Progress) -> Run:
    """GO ray tubes on both reflectors (:func:`raysim.optics.go.trace`): cell means."""
    k_hat, probe, e_hat = scene.source.direction, scene.probe, scene.source.e_hat
    m, lattice_note = go_subdivisions(scene, ideal)
    result_ideal = go.trace(ideal, scene.sphere, k_hat, m, device,
                            _stage(report, 0.05, 0.45, "ideal"), probe, e_hat)
    result_def = go.trace(deformed, scene.sphere, k_hat, m, device,
                          _stage(report, 0.5, 0.45, "deformed"), probe, e_hat)
    attrs = {
        "subdivisions": int(m),
        **({"go_lattice": lattice_note} if lattice_note else {}),
        "rays": int(result_def.n_rays + result_ideal.n_rays),
        "lit_area": result_def.power_lit,
        "lit_area_ideal": result_ideal.power_lit,
        "power_on_sphere": result_def.power_on_grid,
        "power_on_sphere_ideal": result_ideal.power_on_grid,
        "power_balance": result_def.power_balance,
        "power_balance_ideal": result_ideal.power_balance,
        "shadowed_rays": int(result_def.n_shadowed),
    }
    if ideal.obstacles is not None:
        attrs["blocked_rays"] = int(result_def.n_blocked)
    return Run(result_def.intensity, result_ideal.intensity, "cell_mean", attrs,
               blocked_share=result_ideal.blocked_share)


class BlockContext(Protocol):
    """What :meth:`BlockEngine.prepare` returns: one process's context of one simulation."""

    def evaluate(self, lo: int, hi: int, progress: Progress | None = None
                 ) -> tuple[dict[str, NDArray[np.float64]], dict[str, float]]:
        """The engine's arrays (name -> (hi - lo, *tail) float64) at the flattened grid points
        lo..hi-1 (C order over (theta, phi)), and figures of the work (``pairs``, ``seconds``:
        summed over blocks, they go into the Run's attributes)."""
        ...

    def attrs(self) -> dict[str, Any]:
        """What the FieldMap needs from the context, the same in every process (JSON-able):
        ``mesh`` (:func:`scene_attrs`), ``focal_length``, ``diameter`` (m) and ``engine``
        (the engine's own, handed to :meth:`BlockEngine.finish`)."""
        ...

    def digest(self) -> str:
        """A digest of the context's inputs to the sums (equal digests: equal block values)."""
        ...


@dataclass(frozen=True)
class BlockEngine:
    """A method that computes its fields at any block of the sphere's points independently.

    ``parts(options)``: the arrays a block gives, name -> tail shape (float64, one row per
    point). ``prepare(scene, ideal, deformed, options, device, keep)``: the heavy context
    (quadratures, edges, elements), once per process; ``keep`` asks it to keep what it makes
    for further blocks. ``finish(scene, options, context_attrs, arrays, figures)``: the
    context's :meth:`BlockContext.attrs`, the whole grid's arrays (n_theta * n_phi rows) and the
    figures summed over blocks -> :class:`Run`. A point's
    values must not depend on which other points share its block: the FieldMap from many
    blocks is then the single-process one bit for bit.
    """

    parts: Callable[[Options], dict[str, tuple[int, ...]]]
    prepare: Callable[[Scene, Reflector, Reflector, Options, str | None, bool], BlockContext]
    finish: Callable[[Scene, Options, dict, dict[str, NDArray[np.float64]], dict[str, float]], Run]


def run_one_block(method: str) -> Engine:
    """The :data:`ENGINES` entry of a block engine: its whole grid as one block, here."""

    def run(scene: Scene, ideal: Reflector, deformed: Reflector, options: Options,
            device: str | None, report: Progress) -> Run:
        engine = BLOCK_ENGINES[method]
        context = engine.prepare(scene, ideal, deformed, options, device, False)
        arrays, figures = context.evaluate(0, scene.sphere.n_theta * scene.sphere.n_phi,
                                           _stage(report, 0.05, 0.95, "blocks"))
        return engine.finish(scene, options, context.attrs(), arrays, figures)

    return run


def _wave_edges(method: str, options: Options) -> str | None:
    """The edge set of a wave method: None for ``po``, ``options.edges`` or ``rim`` for ``po+ptd``."""
    return (options.edges or "rim") if method == "po+ptd" else None


def _wave_parts(edges: str | None) -> Callable[[Options], dict[str, tuple[int, ...]]]:
    names = ("po_ideal", "po_deformed") + (("edges_ideal", "edges_deformed") if edges else ())
    return lambda options: {name: (6,) for name in names}


def _wave(scene: Scene) -> Any:
    from raysim.optics.illumination import Illumination

    return Illumination.plane_wave(scene.source.frequency_hz, scene.source.direction, scene.source.e_hat)


#: PO's default quadrature (1.5 Gauss points per wavelength) holds while the sphere stays this
#: many wavelengths above the dish's vertex. Measured on a 15 m dish (F = 6 m, 1 GHz) against 6
#: points per wavelength: FA off by 2e-4 of its RMS 10 wavelengths above, 4.4 % 5 above, 60 %
#: one above (where 3 points per wavelength give 4e-4).
NEAR_VERTEX_WAVELENGTHS = 6.0


def quadrature_note(gap_m: float, wavelength_m: float, samples_per_wavelength: float | None) -> dict:
    """FieldMap attributes on PO's quadrature: ``sphere_gap_wavelengths``, how far the sphere's
    lowest point (F - R, m) lies above the vertex in wavelengths, and ``quadrature_warning``
    where that is under :data:`NEAR_VERTEX_WAVELENGTHS` with the default quadrature."""
    gap = gap_m / wavelength_m
    out: dict = {"sphere_gap_wavelengths": float(gap)}
    if samples_per_wavelength is None and gap < NEAR_VERTEX_WAVELENGTHS:
        out["quadrature_warning"] = (
            f"the sphere passes {gap:.2g} wavelengths above the dish's vertex, where PO's default "
            "1.5 samples per wavelength err (FA off by 4 % of its RMS 5 wavelengths above, 60 % "
            "one above): give --samples-per-wavelength 3 or more")
    return out


class _WaveContext:
    """PO currents (and fringe currents of the method's edges) of both reflectors."""

    def __init__(self, scene: Scene, ideal: Reflector, deformed: Reflector, options: Options,
                 device: str | None, keep: bool, method: str) -> None:
        from raysim.optics import po
        from raysim.optics.sources import Sources
        from raysim.surface.quadrature import targets_around

        self.edges = _wave_edges(method, options)
        self.spw = options.samples_per_wavelength or po.DEFAULT_SAMPLES_PER_WAVELENGTH
        wave = _wave(scene)
        reflectors = {"ideal": ideal, "deformed": deformed}
        self.points = {name: scene.sphere.points(r.F).reshape(-1, 3) for name, r in reflectors.items()}
        from raysim.optics.fast.chart import domain_of

        self.radiator, self.radiator_tol = options.radiator, options.radiator_tol
        plans: dict = {}  # the ideal reflector's trees, reused by the deformed one where they hold it

        def make(name: str) -> Sources:
            # the whole job's points set each reflector's quadrature (the integrand's rate on them)
            r = reflectors[name]
            return Sources(r, wave, self.spw, self.edges, device, keep, radiator=options.radiator,
                           tol=options.radiator_tol, plans=plans,
                           targets=targets_around(self.points[name], (0.0, 0.0, float(r.F)), wave.k_hat))

        # the ideal reflector's sources now; the deformed one's when first asked for
        # (:meth:`source`), which :meth:`evaluate` does while the ideal's sum runs: its
        # quadrature, read face by face on the deformed surface, takes seconds at 12 GHz
        self._make = make
        self._sources: dict[str, Sources] = {"ideal": make("ideal")}
        self._making = threading.Lock()  # blocks evaluated at once by a worker's threads make it once
        self.device = self._sources["ideal"].device
        # the whole grid's chart domain: every block of points is summed on the same grids
        self.domains = {name: domain_of(self.points[name], (0.0, 0.0, float(r.F)))
                        for name, r in reflectors.items()}
        self.mesh = scene_attrs(scene, deformed, ideal)
        self.F, self.D = float(deformed.F), float(deformed.D)
        self.quadrature = quadrature_note(ideal.F - scene.sphere.radius, wave.wavelength,
                                          options.samples_per_wavelength)
        self.edge_note = _edge_note(self.edges, deformed, wave.wavelength)

    def evaluate(self, lo: int, hi: int, progress: Progress | None = None):
        report = progress or (lambda stage, fraction: None)
        arrays: dict[str, NDArray[np.float64]] = {}
        figures = {"pairs": 0.0, "seconds": 0.0, "pairs_edges": 0.0, "seconds_edges": 0.0}
        # each reflector's elements made and its trees planned, the ideal's first (the deformed
        # one sums on them where they hold it), and each one's sums started on a thread of its
        # own as soon as they are planned: on the CPU one walk leaves about a sixth of two cores
        # idle, and the deformed reflector's quadrature and elements are made while the ideal's
        # sum runs (the bits are those of one after the other; on a GPU they run one after the
        # other)
        at_once = self.device == "cpu"
        begin = time.perf_counter()
        stop = threading.Event()  # set when this thread unwinds: the other sums stop at their next launch
        with ThreadPoolExecutor(max_workers=2) as pool:
            try:
                pending = []
                for i, name in enumerate(("ideal", "deformed")):
                    stage = _stage(report, 0.5 * i, 0.5, name)
                    run = self.source(name).start(self.points[name][lo:hi], stage, domain=self.domains[name])
                    pending.append((name, pool.submit(runtime.cancellable, stop, run) if at_once else run()))
                if at_once:  # the first error from either thread ends the wait
                    for out in wait([out for _, out in pending], return_when=FIRST_EXCEPTION).done:
                        out.result()  # raises a thread's error
                radiated = {name: out.result() if at_once else out for name, out in pending}
            except BaseException:
                stop.set()
                raise
        wall = time.perf_counter() - begin
        for name, out in radiated.items():
            arrays[f"po_{name}"] = out.sums["electric"]
            if self.edges:
                arrays[f"edges_{name}"] = out.sums["fringe"]
            for key in figures:
                figures[key] += getattr(out, key)
        busy = figures["seconds"] + figures["seconds_edges"]
        if at_once and busy > wall > 0:  # the sums overlapped: their seconds share the wall clock's
            figures["seconds"] *= wall / busy
            figures["seconds_edges"] *= wall / busy
        return arrays, figures

    def source(self, name: str) -> Any:
        """The :class:`~raysim.optics.sources.Sources` of reflector ``name`` (``ideal`` or
        ``deformed``), made on first use."""
        with self._making:
            if name not in self._sources:
                self._sources[name] = self._make(name)
        return self._sources[name]

    def attrs(self) -> dict[str, Any]:
        ideal, deformed = self.source("ideal"), self.source("deformed")
        for sources in (ideal, deformed):
            sources.prime()
        from raysim.surface.quadrature import INTEGRAND_TOL

        # the quadrature follows the integrand's rate on the job's points (each face's Gauss error)
        engine = {"samples_per_wavelength": float(self.spw), "integrand_tol": INTEGRAND_TOL,
                  "samples": int(deformed.stats.n_samples),
                  "samples_lit": int(deformed.stats.n_lit), "samples_lit_ideal": int(ideal.stats.n_lit)}
        if self.edges:
            engine.update({"edge_points": int(deformed.n_edge_points),
                           "edge_points_lit": int(deformed.n_edge_lit), **self.edge_note})
        ran = sorted({m.split(" ")[0] for src in (ideal, deformed) for m in src.methods.values()})
        engine["radiator"] = self.radiator
        if self.radiator == "fast":  # a tolerance governs the fast sum only (and its choice)
            engine["radiator_tol"] = float(self.radiator_tol)
        engine.update({"radiator_ran": ",".join(ran) or self.radiator, **self.quadrature})
        return {"mesh": self.mesh, "focal_length": self.F, "diameter": self.D, "engine": engine}

    def digest(self) -> str:
        return "-".join(self.source(name).digest() for name in ("ideal", "deformed"))


def _finish_wave(method: str) -> Callable[..., Run]:
    def finish(scene: Scene, options: Options, context: dict, arrays: dict[str, NDArray[np.float64]],
               figures: dict[str, float]) -> Run:
        return _wave_run(scene, options, context, arrays, figures, _wave_edges(method, options))

    return finish


def _wave_run(scene: Scene, options: Options, context: dict, arrays: dict[str, NDArray[np.float64]],
              figures: dict[str, float], edges: str | None) -> Run:
    """PO fields of both reflectors (with ``edges``, plus the fringe fields of those edges,
    :mod:`raysim.optics.ptd`) from the raw sums: intensities at the cell centres."""
    from raysim.optics import po
    from raysim.optics.radiator import field_of

    wave = _wave(scene)
    shape = (scene.sphere.n_theta, scene.sphere.n_phi, 3)

    def field(name: str, kind: str) -> NDArray[np.complex128]:
        return field_of({kind: arrays[name]}, wave.k).reshape(shape)

    fields = {"E": field("po_deformed", "electric"), "E_ideal": field("po_ideal", "electric")}
    pairs, seconds = int(figures["pairs"]), float(figures["seconds"])
    attrs = {"field": "total" if options.total else "scattered", **context["engine"], "pairs": pairs,
             "pair_rate": pairs / seconds if seconds > 0 else 0.0}
    if edges is not None:
        E_edges, E_edges_ideal = field("edges_deformed", "fringe"), field("edges_ideal", "fringe")
        fields["E"] = fields["E"] + E_edges
        fields["E_ideal"] = fields["E_ideal"] + E_edges_ideal
        fields["E_edges"], fields["E_edges_ideal"] = E_edges, E_edges_ideal
        attrs.update({"edges": edges, "edge_theory": EDGE_THEORY,
                      "edge_points_per_wavelength": float(_ptd_points_per_wavelength()),
                      "seconds_edges": float(figures.get("seconds_edges", 0.0))})
    if options.total:
        E_inc = po.incident_field(scene.sphere.points(context["focal_length"]), wave.k, wave.k_hat,
                                  wave.e_hat)
        fields["E"] = fields["E"] + E_inc.reshape(shape)
        fields["E_ideal"] = fields["E_ideal"] + E_inc.reshape(shape)
    run = Run(probe_power(scene, fields["E"]), probe_power(scene, fields["E_ideal"]), "centre",
              attrs)
    if options.save_field:
        run.extra = field_variables(fields, attrs["field"])
        run.coords = {"component": ("component", ["x", "y", "z"])}
    return run


def probe_power(scene: Scene, E: NDArray[np.complex128]) -> NDArray[np.float64]:
    """What the scene's probe reads (n_theta, n_phi) of the complex field E (n_theta, n_phi,
    3) at the cell centres: |E|^2 for the ideal meter; otherwise the field taken to arrive as
    the ideal dish's rays do, on the probe's boresight (:func:`raysim.maps.probe.arrival_directions`)."""
    from raysim.maps.probe import arrival_directions

    if scene.probe.ideal:
        return np.sum(np.abs(E) ** 2, axis=-1)
    return scene.probe.power(E, arrival_directions(scene.sphere.directions()))


def _run_go_edge(scene: Scene, ideal: Reflector, deformed: Reflector, options: Options,
                 device: str | None, report: Progress) -> Run:
    """Method ``go+edge`` (:mod:`raysim.optics.goedge`): the geometric wave of ray tubes plus
    the diffraction of every free edge, on both reflectors, and (``options.fresnel``) the
    deformed geometric wave's Fresnel-zone correction (:mod:`raysim.optics.fresnel`);
    intensities at the cell centres."""
    from raysim.optics import fresnel, goedge, po
    from raysim.optics.bvh import ReflectorBVH

    wave = po.Illumination.plane_wave(scene.source.frequency_hz, scene.source.direction,
                                      scene.source.e_hat)
    bvh = ReflectorBVH.build(ideal, device)
    results = {}
    for k, (name, reflector) in enumerate((("ideal", ideal), ("deformed", deformed))):
        report(f"{name}: rays and edges", 0.05 + 0.45 * k)
        if k == 1:
            bvh.refit(deformed)  # same triangulation: the ideal BVH moved
        results[name] = goedge.sphere_field(reflector, scene.sphere, wave, None, scene.subdivisions or 1,
                                            device=device, bvh=bvh)
    r_def, r_ideal = results["deformed"], results["ideal"]
    fix = None
    if options.fresnel:
        report("deformed: Fresnel-zone correction", 0.95)
        fix = fresnel.correction(ideal, deformed, scene.sphere, wave, r_ideal.E_geo,
                                 r_def.subdivisions, device)
    fields = {"E": r_def.E if fix is None else r_def.E + fix.dE, "E_ideal": r_ideal.E}
    attrs = {
        "field": "total" if options.total else "scattered",
        "edges": "all",
        "edge_theory": goedge.EDGE_THEORY,
        "edge_points_per_wavelength": float(goedge.DEFAULT_POINTS_PER_WAVELENGTH),
        "edge_points": int(r_def.n_edge_points),
        "edge_points_lit": int(r_def.n_edge_lit),
        "subdivisions": int(r_def.subdivisions),
        "rays": int(r_def.n_rays + r_ideal.n_rays),
        "tubes": int(r_def.n_tubes),
        "seconds_trace": r_def.seconds_trace + r_ideal.seconds_trace,
        "seconds_edges": r_def.seconds_edges + r_ideal.seconds_edges,
        **(fix.attrs() if fix is not None else {"fresnel_correction": (
            f"none: {fresnel.applies(deformed, wave)}" if options.fresnel else "off")}),
    }
    if options.total:
        E_inc = po.incident_field(scene.sphere.points(deformed.F), wave.k, wave.k_hat, wave.e_hat)
        fields = {name: E + E_inc.reshape(E.shape) for name, E in fields.items()}
    run = Run(probe_power(scene, fields["E"]), probe_power(scene, fields["E_ideal"]), "centre",
              attrs)
    if options.save_field:
        fields.update({"E_geo": r_def.E_geo, "E_geo_ideal": r_ideal.E_geo, "E_edges": r_def.E_edge,
                       "E_edges_ideal": r_ideal.E_edge})
        if fix is not None:
            fields["E_fresnel"] = fix.dE
        run.extra = field_variables(fields, attrs["field"])
        run.coords = {"component": ("component", ["x", "y", "z"])}
    return run


EDGE_THEORY = "Michaeli fringe equivalent edge currents of a half-plane (raysim.optics.ptd)"


def _edge_note(edges: str | None, deformed: Reflector, wavelength: float) -> dict:
    """The FieldMap's caveat on panel-gap edges (``edges`` ``all`` with gaps), else nothing."""
    layout = deformed.layout
    if edges != "all" or layout is None or not layout.gap > 0:
        return {}
    return {"edge_gap_wavelengths": layout.gap / wavelength,
            "edge_note": ("each panel edge is an isolated half-plane: the fringe currents of a "
                          "gap's two edges add whatever the gap's width, which holds for gaps "
                          "wider than about a wavelength only")}


def _ptd_points_per_wavelength() -> float:
    from raysim.optics import ptd

    return float(ptd.DEFAULT_POINTS_PER_WAVELENGTH)


def field_variables(fields: dict[str, NDArray[np.complex128]], kind: str) -> dict:
    """FieldMap variables ``NAME_re`` / ``NAME_im`` of complex fields (theta, phi, component)."""
    dims = ("theta", "phi", "component")
    unit = {"units": "1", "reference": "incident plane-wave E amplitude",
            "component": "x, y, z in the reflector frame", "field": kind}
    extra = {}
    for name, E in fields.items():
        extra[f"{name}_re"] = (dims, E.real, {**unit, "long_name": f"real part of {name}"})
        extra[f"{name}_im"] = (dims, E.imag, {**unit, "long_name": f"imaginary part of {name}"})
    return extra


def _wave_engine(method: str) -> BlockEngine:
    def prepare(scene, ideal, deformed, options, device, keep):
        return _WaveContext(scene, ideal, deformed, options, device, keep, method)

    edges = "rim" if method == "po+ptd" else None
    return BlockEngine(_wave_parts(edges), prepare, _finish_wave(method))


BLOCK_ENGINES: dict[str, BlockEngine] = {"po": _wave_engine("po"), "po+ptd": _wave_engine("po+ptd")}
ENGINES: dict[str, Engine] = {"go": _run_go, "po": run_one_block("po"), "po+ptd": run_one_block("po+ptd"),
                              "go+edge": _run_go_edge}


def ideal_resolution(scene: Scene) -> float:
    """Triangle edge (m) of the generated mesh, or NaN for a mesh loaded from a file."""
    return float(scene.dish.resolution) if scene.dish.mesh is None else math.nan


STEERABLE_DISH_M = 110.0  # the largest fully steerable paraboloids (GBT, Effelsberg: 100 m)
#: a mesh file's dish above this is more likely a file in millimetres than a reflector
LARGEST_DISH_M = 150.0


def mesh_size_warning(D: float, fix: str = "set dish.mesh_unit_m = 0.001") -> str:
    """What to say of a mesh file's dish of diameter ``D`` (m) above :data:`LARGEST_DISH_M`
    (more likely a file in millimetres than a reflector), with the ``fix``; "" below it."""
    if not D > LARGEST_DISH_M:
        return ""
    return (f"the mesh's dish is {D:.4g} m across, larger than any steerable reflector "
            f"({STEERABLE_DISH_M:g} m): if the file is in millimetres, {fix}")


def summary(ds: xr.Dataset) -> str:
    """One line: points, rays, time and power balance of a simulated FieldMap (and PO's
    quadrature warning, the panel-gap edges' warning, a rim image beyond the hemisphere, why an
    asked-for Fresnel correction was not applied, a mesh file's departure from its ideal, and
    a mesh file's dish too large for a dish in metres, where the map has them)."""
    line = _engine_summary(ds)
    if "quadrature_warning" in ds.attrs:
        line += f"; WARNING: {ds.attrs['quadrature_warning']}"
    if ds.attrs.get("edge_gap_wavelengths", math.inf) < 1.0:
        line += (f"; WARNING: the panel gaps are {ds.attrs['edge_gap_wavelengths']:.3g} wavelengths "
                 "wide, and --edges all treats each gap edge as a lone half-plane, which "
                 "overstates gaps narrower than a wavelength (docs/engines.md)")
    size = mesh_size_warning(float(ds.attrs.get("diameter", 0.0)))
    beyond = rim_beyond_hemisphere(ds.attrs)
    if beyond:
        line += f"; WARNING: {beyond}"
    if str(ds.attrs.get("fresnel_correction", "")).startswith("none: "):
        line += f"; --fresnel not applied: {ds.attrs['fresnel_correction'][6:]}"
    if "mesh_departure_rms_m" in ds.attrs and size:
        line += f"; WARNING: {size}"
    for warning in ray_optics_warnings(ds.attrs):
        line += f"; WARNING: {warning}"
    shadowed = self_shadow_warning(ds.attrs)
    if shadowed:
        line += f"; WARNING: {shadowed}"
    if "go_lattice" in ds.attrs:
        line += f"; {ds.attrs['go_lattice']}"
    if "mesh_departure_rms_m" in ds.attrs:
        line += (f"; the mesh departs {ds.attrs['mesh_departure_rms_m'] * 1e6:.3g} um RMS along z "
                 "from its ideal (its deformation; a file not in the reflector frame adds to it)")
    return line


#: GO and go+edge: a dish fewer wavelengths across than this, or a sphere fewer focal-spot
#: widths (lambda F / D) in radius than this, is said to be outside their reach
MIN_GO_WAVELENGTHS = 10.0
MIN_GO_SPOTS = 10.0
#: share of the lit power that may miss the sphere's cells before the summary says so
MISSED_POWER_SHARE = 0.01


def ray_optics_warnings(attrs) -> list[str]:
    """What a GO or go+edge FieldMap (``attrs``) should say of its own validity, each a
    phrase: a dish a few wavelengths across (a 10 m dish at 50 MHz, 1.7 wavelengths, ran all
    four engines without a word); a sphere so near the focus that it lies in the focal spot's
    region, where GO's rays converge to a caustic (R = 1 mm: GO peaked at 2.7e7 where PO gives
    2.2e3; at 4 spot widths GO was 0.5 to 24 times PO ring by ring); go+edge with
    obstacles, whose shadows on the dish carry no edge term (14 % RMS from PO + PTD outside
    the blocked cells in a QA case, 0.2 % without the obstacle); and GO power that missed the
    sphere's cells (off-axis incidence: 47 % at 24 deg, shown only as the power balance)."""
    method = attrs.get("method")
    if method not in ("go", "go+edge"):
        return []
    out = []
    try:
        f, D, F, R = (float(attrs[k]) for k in ("frequency_hz", "diameter", "focal_length",
                                                "sphere_radius"))
    except (KeyError, TypeError, ValueError):
        f = D = F = R = math.nan
    wavelength = 299_792_458.0 / f if f > 0 else math.nan
    if D / wavelength < MIN_GO_WAVELENGTHS:
        out.append(f"the dish is {D / wavelength:.3g} wavelengths across: {method} needs a dish many "
                   "wavelengths across; compare with --method po+ptd")
    spot = wavelength * F / D
    if R / spot < MIN_GO_SPOTS:
        out.append(f"the sphere's radius is {R / spot:.3g} focal-spot widths (lambda F / D = "
                   f"{spot:.3g} m): within a few widths of the focus the rays converge toward a "
                   f"caustic that {method} does not resolve (a QA run: GO 0.5 to 24 times PO ring "
                   "by ring at 4 widths); compare with --method po+ptd")
    if method == "go+edge" and str(attrs.get("obstacles", "none")) not in ("", "none"):
        out.append("go+edge gives the obstacles' shadows on the dish no edge term: near their "
                   "images the field departs from PO + PTD (docs/engines.md)")
    balance = attrs.get("power_balance")
    if method == "go" and isinstance(balance, (int, float)) and balance < -MISSED_POWER_SHARE:
        out.append(f"{-100 * float(balance):.3g} % of the lit power misses the sphere's cells "
                   "(rays beyond its theta and phi range)")
    return out


def self_shadow_warning(attrs) -> str:
    """What to say of a PO or PO + PTD map whose plane wave arrives further off axis than
    atan(4F / D), the angle of the rim's tangent: the dish then hides part of its own concave
    face from the wave and lights part of its back. PO tells lit from shadowed per mesh face,
    so its error there follows the faces' size (a QA case, a 10 m dish of F = 2 m at 0.3 GHz
    and 55 deg: E 25 % off an independent PO integral on 1 m faces, 14 % on 0.5 m, 2.4 % on
    0.25 m, 1.5 % on 0.125 m, where at 20 deg 1 m faces gave 7e-5); "" otherwise."""
    if attrs.get("method") not in ("po", "po+ptd"):
        return ""
    try:
        D, F = float(attrs["diameter"]), float(attrs["focal_length"])
        tilt = abs(float(attrs.get("incidence_theta", 0.0)))
    except (KeyError, TypeError, ValueError):
        return ""
    limit = math.atan(4.0 * F / D) if D > 0 and F > 0 else math.inf
    if not tilt > limit:
        return ""
    return (f"the wave arrives {math.degrees(tilt):.1f} deg off axis, beyond the rim's tangent at "
            f"{math.degrees(limit):.1f} deg (atan 4F/D): the dish shadows part of its own face, "
            "which PO tells from the lit part face by face, so the field errs by some percent "
            "unless the faces are a few tenths of a wavelength (dish.resolution_m; 0.25 "
            "wavelengths gave 2.4 %)")


def rim_beyond_hemisphere(attrs) -> str:
    """What to say of a dish whose rim image, 2 atan(D / 4F) from the axis at the focus, lies
    beyond theta = 90 deg (F/D below 0.25): no hemisphere scan sees its outer ring, and
    ``raysim invert`` refuses a scan that stops short of the rim image; "" otherwise."""
    try:
        D, F = float(attrs["diameter"]), float(attrs["focal_length"])
    except (KeyError, TypeError, ValueError):
        return ""
    if not (D > 0 and F > 0) or theta_rim(D, F) <= 0.5 * math.pi + 1e-12:
        return ""
    return (f"the rim image lies at {math.degrees(theta_rim(D, F)):.1f} deg from the axis, "
            f"beyond the hemisphere (F/D {F / D:.3g}, below 0.25): no hemisphere scan sees the "
            "dish's outer ring, and raysim invert refuses a scan short of the rim image")


def _engine_summary(ds: xr.Dataset) -> str:
    n = ds.sizes["theta"] * ds.sizes["phi"]
    lit = np.isfinite(ds["intensity"].values) & (ds["intensity"].values > 0)
    if ds.attrs.get("method") == "go+edge":
        return (f"{n} points, {ds.attrs.get('rays', 0):,} rays, {ds.attrs.get('edge_points', 0):,} edge "
                f"points per reflector, {ds.attrs.get('seconds_total', float('nan')):.1f} s (trace "
                f"{ds.attrs.get('seconds_trace', float('nan')):.1f} s, edges "
                f"{ds.attrs.get('seconds_edges', float('nan')):.1f} s)")
    if ds.attrs.get("method") in WAVE_METHODS:
        edges = (f"{ds.attrs['edges']} edges ({ds.attrs.get('edge_points', 0):,} points), "
                 if "edges" in ds.attrs else "")
        return (f"{n} points, {ds.attrs.get('samples', 0):,} samples per reflector, {edges}"
                f"{ds.attrs.get('pairs', 0):,} pairs at {ds.attrs.get('pair_rate', 0.0) / 1e6:.0f} M/s, "
                f"{ds.attrs.get('seconds_total', float('nan')):.1f} s")
    return (f"{n} points ({int(lit.sum())} lit), {ds.attrs.get('rays', 0):,} rays, "
            f"{ds.attrs.get('seconds_total', float('nan')):.1f} s, power balance "
            f"{ds.attrs.get('power_balance', float('nan')):+.1e} (ideal "
            f"{ds.attrs.get('power_balance_ideal', float('nan')):+.1e})")


class _CallableModule(types.ModuleType):
    """This module, callable as :func:`simulate`. ``raysim.simulate`` is the package's public
    function, but importing this module binds the module itself to that name (Python sets a
    package's attribute to each submodule it loads), after which ``raysim.simulate(scene)``
    would call a module. Calling the module calls :func:`simulate` (looked up at each call)."""

    def __call__(self, *args: Any, **kwargs: Any) -> xr.Dataset:
        return simulate(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
