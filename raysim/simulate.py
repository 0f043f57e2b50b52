"""Scene -> FieldMap: build the ideal and deformed reflectors, run an engine on both.

``simulate(scene)`` is the library's main entry point (the ``raysim simulate`` command is a
thin layer over it). The FieldMap it returns carries both intensities, the scene's TOML text
and the run's figures (rays, power balance, times) as flat attributes.

Each method is one engine function in :data:`ENGINES`, ``(scene, ideal, deformed, options,
device, progress) -> Run``: the two intensities on the scene's sphere grid, how they are sampled
(GO cell means, wave-optics cell centres) and the engine's own attributes and variables. What
every method shares (the reflectors, the scene's attributes, the FieldMap) is done once here.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from raysim.errors import RaysimError
from raysim.maps.fieldmap import fieldmap
from raysim.optics import go
from raysim.optics.runtime import Progress
from raysim.scene import Scene
from raysim.surface.mesh import Reflector, reflectors_for

METHODS = ("go", "po", "po+ptd", "go+edge")


@dataclass(frozen=True)
class Options:
    """Engine options beyond the scene (see :func:`simulate`)."""

    total: bool = False
    save_field: bool = False
    samples_per_wavelength: float | None = None
    edges: str | None = None


@dataclass
class Run:
    """What an engine hands back: intensities (n_theta, n_phi) relative to the incident wave."""

    intensity: NDArray[np.float64]
    intensity_ideal: NDArray[np.float64]
    sampling: str  # "cell_mean" or "centre" (the FieldMap contract)
    attrs: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)  # further FieldMap variables
    coords: dict = field(default_factory=dict)


Engine = Callable[[Scene, Reflector, Reflector, Options, str | None, Progress], Run]


def scene_attrs(scene: Scene, deformed: Reflector) -> dict:
    """The FieldMap attributes that describe the scene and its mesh, whatever the method."""
    return {
        "scene_name": scene.name,
        "deformation": scene.deformation.describe(),
        "incidence_theta": scene.source.incidence_theta,
        "incidence_phi": scene.source.incidence_phi,
        "polarization": scene.source.polarization,
        "mesh_resolution": ideal_resolution(scene),
        "mesh_faces": len(deformed.faces),
        "panels": int(deformed.n_panels),
    }


def simulate(scene: Scene, method: str | None = None, device: str | None = "cpu",
             progress: Progress | None = None, *, total: bool = False, save_field: bool = False,
             samples_per_wavelength: float | None = None, edges: str | None = None) -> xr.Dataset:
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
    """
    method = scene.method if method is None else method
    if method not in ENGINES:
        raise RaysimError(f"unknown method {method!r}: use one of {', '.join(METHODS)}")
    options = Options(total, save_field, samples_per_wavelength, edges)
    _check_options(method, options)
    report = progress or (lambda stage, fraction: None)
    start = time.perf_counter()
    report("mesh", 0.0)
    ideal, deformed = reflectors_for(scene)
    mesh_seconds = time.perf_counter() - start
    run = ENGINES[method](scene, ideal, deformed, options, device, report)
    report("done", 1.0)
    attrs = {**scene_attrs(scene, deformed), **run.attrs, "device": str(device or "cpu"),
             "seconds_mesh": mesh_seconds, "seconds_total": time.perf_counter() - start}
    ds = fieldmap(scene.sphere, run.intensity, run.intensity_ideal, focal_length=deformed.F,
                  diameter=deformed.D, frequency_hz=scene.source.frequency_hz, method=method,
                  sampling=run.sampling, scene=scene.text, attrs=attrs, extra=run.extra)
    return ds.assign_coords(run.coords) if run.coords else ds


def _check_options(method: str, options: Options) -> None:
    """Refuse options that do not apply to ``method`` (one line for the user)."""
    if options.edges is not None and method != "po+ptd":
        raise RaysimError("--edges applies to --method po+ptd only")
    if options.edges is not None and options.edges not in ("rim", "all"):
        raise RaysimError(f"unknown edge set {options.edges!r}: use rim or all")
    wave_only = options.total or options.save_field or options.samples_per_wavelength is not None
    if method == "go" and wave_only:
        raise RaysimError("--total, --save-field and --samples-per-wavelength apply to --method po "
                          "and po+ptd only")
    if method == "go+edge" and options.samples_per_wavelength is not None:
        raise RaysimError("--samples-per-wavelength applies to --method po and po+ptd only")
    spw = options.samples_per_wavelength
    if spw is not None and not (math.isfinite(spw) and spw > 0):
        raise RaysimError(f"--samples-per-wavelength must be > 0, got {spw:g}")


def _stage(report: Progress, offset: float, width: float, label: str) -> Progress:
    """A sub-progress for one reflector: its fractions mapped onto offset..offset + width."""
    return lambda name, f: report(f"{label}: {name}", offset + width * f)


def _run_go(scene: Scene, ideal: Reflector, deformed: Reflector, options: Options,
            device: str | None, report: Progress) -> Run:
    """GO ray tubes on both reflectors (:func:`raysim.optics.go.trace`): cell means."""
    k_hat = scene.source.direction
    result_ideal = go.trace(ideal, scene.sphere, k_hat, scene.subdivisions, device,
                            _stage(report, 0.05, 0.45, "ideal"))
    result_def = go.trace(deformed, scene.sphere, k_hat, scene.subdivisions, device,
                          _stage(report, 0.5, 0.45, "deformed"))
    attrs = {
        "subdivisions": int(scene.subdivisions),
        "rays": int(result_def.n_rays + result_ideal.n_rays),
        "lit_area": result_def.power_lit,
        "lit_area_ideal": result_ideal.power_lit,
        "power_on_sphere": result_def.power_on_grid,
        "power_on_sphere_ideal": result_ideal.power_on_grid,
        "power_balance": result_def.power_balance,
        "power_balance_ideal": result_ideal.power_balance,
        "shadowed_rays": int(result_def.n_shadowed),
    }
    return Run(result_def.intensity, result_ideal.intensity, "cell_mean", attrs)


def _run_po(scene: Scene, ideal: Reflector, deformed: Reflector, options: Options,
            device: str | None, report: Progress) -> Run:
    """Method ``po``: the PO currents alone."""
    return _run_wave(scene, ideal, deformed, options, device, report, edges=None)


def _run_po_ptd(scene: Scene, ideal: Reflector, deformed: Reflector, options: Options,
                device: str | None, report: Progress) -> Run:
    """Method ``po+ptd``: the PO currents plus the fringe currents of ``options.edges``
    (``rim`` unless given)."""
    return _run_wave(scene, ideal, deformed, options, device, report, edges=options.edges or "rim")


def _run_wave(scene: Scene, ideal: Reflector, deformed: Reflector, options: Options,
              device: str | None, report: Progress, edges: str | None) -> Run:
    """PO currents on both reflectors (:func:`raysim.optics.po.sphere_field`), with ``edges``
    (``rim`` or ``all``) the fringe field of those edges added (:mod:`raysim.optics.ptd`):
    intensities at the cell centres."""
    from raysim.optics import po, ptd

    spw = options.samples_per_wavelength or po.DEFAULT_SAMPLES_PER_WAVELENGTH
    wave = po.Illumination.plane_wave(scene.source.frequency_hz, scene.source.direction,
                                      scene.source.e_hat)
    result_ideal = po.sphere_field(ideal, scene.sphere, wave, spw, device,
                                   progress=_stage(report, 0.05, 0.475, "ideal"))
    result_def = po.sphere_field(deformed, scene.sphere, wave, spw, device,
                                 progress=_stage(report, 0.525, 0.475, "deformed"))
    fields = {"E": result_def.E, "E_ideal": result_ideal.E}
    pairs = result_ideal.pairs + result_def.pairs
    radiate_seconds = result_ideal.seconds_radiate + result_def.seconds_radiate
    attrs = {
        "field": "total" if options.total else "scattered",
        "samples_per_wavelength": float(spw),
        "samples": int(result_def.n_samples),
        "samples_lit": int(result_def.n_lit),
        "samples_lit_ideal": int(result_ideal.n_lit),
        "pairs": int(pairs),
        "pair_rate": pairs / radiate_seconds if radiate_seconds > 0 else 0.0,
    }
    if edges is not None:
        fringe = {name: ptd.sphere_edge_field(reflector, scene.sphere, wave, edges, device=device,
                                              progress=lambda s, f, n=name: report(f"{n}: {s}", 1.0))
                  for name, reflector in (("ideal", ideal), ("deformed", deformed))}
        fields["E"] = fields["E"] + fringe["deformed"].E
        fields["E_ideal"] = fields["E_ideal"] + fringe["ideal"].E
        fields["E_edges"], fields["E_edges_ideal"] = fringe["deformed"].E, fringe["ideal"].E
        attrs.update(_edge_attrs(edges, fringe, deformed, wave.wavelength))
    if options.total:
        E_inc = po.incident_field(scene.sphere.points(deformed.F), wave.k, wave.k_hat, wave.e_hat)
        fields["E"] = fields["E"] + E_inc.reshape(fields["E"].shape)
        fields["E_ideal"] = fields["E_ideal"] + E_inc.reshape(fields["E"].shape)
    run = Run(np.sum(np.abs(fields["E"]) ** 2, axis=-1), np.sum(np.abs(fields["E_ideal"]) ** 2, axis=-1),
              "centre", attrs)
    if options.save_field:
        run.extra = field_variables(fields, attrs["field"])
        run.coords = {"component": ("component", ["x", "y", "z"])}
    return run


def _run_go_edge(scene: Scene, ideal: Reflector, deformed: Reflector, options: Options,
                 device: str | None, report: Progress) -> Run:
    """Method ``go+edge`` (:mod:`raysim.optics.goedge`): the geometric wave of ray tubes plus
    the diffraction of every free edge, on both reflectors; intensities at the cell centres."""
    from raysim.optics import goedge, po
    from raysim.optics.bvh import ReflectorBVH

    wave = po.Illumination.plane_wave(scene.source.frequency_hz, scene.source.direction,
                                      scene.source.e_hat)
    bvh = ReflectorBVH.build(ideal, device)
    results = {}
    for k, (name, reflector) in enumerate((("ideal", ideal), ("deformed", deformed))):
        report(f"{name}: rays and edges", 0.05 + 0.45 * k)
        if k == 1:
            bvh.refit(deformed)  # same triangulation: the ideal BVH moved
        results[name] = goedge.sphere_field(reflector, scene.sphere, wave, None, scene.subdivisions,
                                            device=device, bvh=bvh)
    r_def, r_ideal = results["deformed"], results["ideal"]
    fields = {"E": r_def.E, "E_ideal": r_ideal.E}
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
    }
    if options.total:
        E_inc = po.incident_field(scene.sphere.points(deformed.F), wave.k, wave.k_hat, wave.e_hat)
        fields = {name: E + E_inc.reshape(E.shape) for name, E in fields.items()}
    run = Run(np.sum(np.abs(fields["E"]) ** 2, axis=-1), np.sum(np.abs(fields["E_ideal"]) ** 2, axis=-1),
              "centre", attrs)
    if options.save_field:
        fields.update({"E_geo": r_def.E_geo, "E_geo_ideal": r_ideal.E_geo, "E_edges": r_def.E_edge,
                       "E_edges_ideal": r_ideal.E_edge})
        run.extra = field_variables(fields, attrs["field"])
        run.coords = {"component": ("component", ["x", "y", "z"])}
    return run


def _edge_attrs(edges: str, fringe: dict, deformed: Reflector, wavelength: float) -> dict:
    """The FieldMap attributes of the PTD edge currents."""
    from raysim.optics import ptd

    attrs = {
        "edges": edges,
        "edge_theory": "Michaeli fringe equivalent edge currents of a half-plane (raysim.optics.ptd)",
        "edge_points_per_wavelength": float(ptd.DEFAULT_POINTS_PER_WAVELENGTH),
        "edge_points": int(fringe["deformed"].n_points),
        "edge_points_lit": int(fringe["deformed"].n_lit),
        "seconds_edges": fringe["ideal"].seconds + fringe["deformed"].seconds,
    }
    layout = deformed.layout
    if edges == "all" and layout is not None and layout.gap > 0:
        attrs["edge_gap_wavelengths"] = layout.gap / wavelength
        attrs["edge_note"] = ("each panel edge is an isolated half-plane: the fringe currents of a "
                              "gap's two edges add whatever the gap's width, which holds for gaps "
                              "wider than about a wavelength only")
    return attrs


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


ENGINES: dict[str, Engine] = {"go": _run_go, "po": _run_po, "po+ptd": _run_po_ptd, "go+edge": _run_go_edge}


def ideal_resolution(scene: Scene) -> float:
    """Triangle edge (m) of the generated mesh, or NaN for a mesh loaded from a file."""
    return float(scene.dish.resolution) if scene.dish.mesh is None else math.nan


def summary(ds: xr.Dataset) -> str:
    """One line: points, rays, time and power balance of a simulated FieldMap."""
    n = ds.sizes["theta"] * ds.sizes["phi"]
    lit = np.isfinite(ds["intensity"].values) & (ds["intensity"].values > 0)
    if ds.attrs.get("method") == "go+edge":
        return (f"{n} points, {ds.attrs.get('rays', 0):,} rays, {ds.attrs.get('edge_points', 0):,} edge "
                f"points per reflector, {ds.attrs.get('seconds_total', float('nan')):.1f} s (trace "
                f"{ds.attrs.get('seconds_trace', float('nan')):.1f} s, edges "
                f"{ds.attrs.get('seconds_edges', float('nan')):.1f} s)")
    if ds.attrs.get("method") in ("po", "po+ptd"):
        edges = (f"{ds.attrs['edges']} edges ({ds.attrs.get('edge_points', 0):,} points), "
                 if "edges" in ds.attrs else "")
        return (f"{n} points, {ds.attrs.get('samples', 0):,} samples per reflector, {edges}"
                f"{ds.attrs.get('pairs', 0):,} pairs at {ds.attrs.get('pair_rate', 0.0) / 1e6:.0f} M/s, "
                f"{ds.attrs.get('seconds_total', float('nan')):.1f} s")
    return (f"{n} points ({int(lit.sum())} lit), {ds.attrs.get('rays', 0):,} rays, "
            f"{ds.attrs.get('seconds_total', float('nan')):.1f} s, power balance "
            f"{ds.attrs.get('power_balance', float('nan')):+.1e} (ideal "
            f"{ds.attrs.get('power_balance_ideal', float('nan')):+.1e})")
