"""Scene -> FieldMap: build the ideal and deformed reflectors, run an engine on both.

``simulate(scene)`` is the library's main entry point (the ``raysim simulate`` command is a
thin layer over it). The FieldMap it returns carries both intensities, the scene's TOML text
and the run's figures (rays, power balance, times) as flat attributes.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
import xarray as xr

from raysim.errors import RaysimError
from raysim.maps.fieldmap import fieldmap
from raysim.methods import METHODS, WAVE_METHODS
from raysim.optics import go
from raysim.scene.scene import Scene
from raysim.surface.mesh import Reflector, reflectors_for

Progress = Callable[[str, float], None]


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


MAX_PO_SAMPLES = 1e8  # source samples per reflector (memory grows with them)


def check_options(scene: Scene, *, method: str, device: str | None = "cpu", total: bool = False,
                  save_field: bool = False, samples_per_wavelength: float | None = None,
                  edges: str | None = None) -> None:
    """Refuse options :func:`simulate` cannot honour, before any work (RaysimError)."""
    if method not in METHODS:
        raise RaysimError(f"unknown method {method!r}: use one of {', '.join(METHODS)}")
    if edges is not None and method != "po+ptd":
        raise RaysimError("--edges applies to --method po+ptd only")
    if edges is not None and edges not in ("rim", "all"):
        raise RaysimError(f"unknown edge set {edges!r}: use rim or all")
    if method not in WAVE_METHODS and (total or save_field or samples_per_wavelength is not None):
        raise RaysimError("--total, --save-field and --samples-per-wavelength apply to --method po "
                          "and po+ptd only")
    if samples_per_wavelength is not None and not (
            math.isfinite(samples_per_wavelength) and 0 < samples_per_wavelength <= 20):
        raise RaysimError(f"--samples-per-wavelength must lie in (0, 20], got {samples_per_wavelength:g}")
    if method in WAVE_METHODS and scene.dish.diameter is not None:
        from raysim.optics.po import DEFAULT_SAMPLES_PER_WAVELENGTH

        spw = samples_per_wavelength or DEFAULT_SAMPLES_PER_WAVELENGTH
        samples = math.pi * (scene.D / 2) ** 2 / (scene.source.wavelength / spw) ** 2
        if samples > MAX_PO_SAMPLES:
            raise RaysimError(f"{method} at {scene.source.frequency_hz:g} Hz needs about "
                              f"{samples:.2g} source samples per reflector (at most "
                              f"{MAX_PO_SAMPLES:.0g}): use go, or a lower frequency")
    from raysim.optics.runtime import resolve_device

    resolve_device(device)


def simulate(scene: Scene, method: str | None = None, device: str | None = "cpu",
             progress: Progress | None = None, *, total: bool = False, save_field: bool = False,
             samples_per_wavelength: float | None = None, edges: str | None = None) -> xr.Dataset:
    """Simulate ``scene`` and return its FieldMap (an ``xarray.Dataset``; see raysim.maps.fieldmap).

    Parameters
    ----------
    scene : a validated scene (``raysim.load_scene``).
    method : ``go`` (geometric optics), ``po`` (physical optics) or ``po+ptd`` (PO plus the
        fringe field of the edges, :mod:`raysim.optics.ptd`); None takes the scene's ``method``.
    device : ``cpu`` or ``cuda`` (Warp device).
    progress : optional callback (stage name, fraction done in 0..1).
    total : PO only: intensity of the total field (scattered plus incident) at the probe,
        instead of the scattered field alone.
    save_field : PO only: also store the complex field components (V/m per V/m incident).
    samples_per_wavelength : PO only: Gauss points per wavelength along the mesh faces'
        edges (default :data:`raysim.optics.po.DEFAULT_SAMPLES_PER_WAVELENGTH`).
    edges : ``po+ptd`` only: ``rim`` (the outer rim, the paper's PTD; the default) or ``all``
        (the rim and every panel edge beside a gap).
    """
    method = scene.method if method is None else method
    check_options(scene, method=method, device=device, total=total, save_field=save_field,
                  samples_per_wavelength=samples_per_wavelength, edges=edges)
    report = progress or (lambda stage, fraction: None)
    if method in WAVE_METHODS:
        return _simulate_po(scene, device, report, total, save_field, samples_per_wavelength,
                            edges=(edges or "rim") if method == "po+ptd" else None)
    start = time.perf_counter()
    report("mesh", 0.0)
    ideal, deformed = reflectors_for(scene)
    mesh_seconds = time.perf_counter() - start
    k_hat = scene.source.direction

    def stage(offset: float, label: str) -> Progress:
        return lambda name, f: report(f"{label}: {name}", offset + 0.45 * f)

    result_ideal = go.trace(ideal, scene.sphere, k_hat, scene.subdivisions, device,
                            stage(0.05, "ideal"))
    result_def = go.trace(deformed, scene.sphere, k_hat, scene.subdivisions, device,
                          stage(0.5, "deformed"))
    report("done", 1.0)
    seconds = time.perf_counter() - start
    attrs = {
        **scene_attrs(scene, deformed),
        "subdivisions": int(scene.subdivisions),
        "rays": int(result_def.n_rays + result_ideal.n_rays),
        "lit_area": result_def.power_lit,
        "lit_area_ideal": result_ideal.power_lit,
        "power_on_sphere": result_def.power_on_grid,
        "power_on_sphere_ideal": result_ideal.power_on_grid,
        "power_balance": result_def.power_balance,
        "power_balance_ideal": result_ideal.power_balance,
        "shadowed_rays": int(result_def.n_shadowed),
        "device": str(device or "cpu"),
        "seconds_mesh": mesh_seconds,
        "seconds_total": seconds,
    }
    return fieldmap(
        scene.sphere, result_def.intensity, result_ideal.intensity,
        focal_length=deformed.F, diameter=deformed.D, frequency_hz=scene.source.frequency_hz,
        method="go", sampling="cell_mean", scene=scene.text, attrs=attrs,
    )


def _simulate_po(scene: Scene, device: str | None, report: Progress, total: bool, save_field: bool,
                 samples_per_wavelength: float | None, edges: str | None = None) -> xr.Dataset:
    """The PO branch of :func:`simulate`: both reflectors through :func:`raysim.optics.po.sphere_field`,
    intensities at the cell centres (``sampling = centre``). With ``edges`` (``rim`` or
    ``all``) the fringe field of those edges (:func:`raysim.optics.ptd.sphere_edge_field`) is added:
    method ``po+ptd``."""
    from raysim.optics import po, ptd

    spw = po.DEFAULT_SAMPLES_PER_WAVELENGTH if samples_per_wavelength is None else samples_per_wavelength
    start = time.perf_counter()
    report("mesh", 0.0)
    ideal, deformed = reflectors_for(scene)
    mesh_seconds = time.perf_counter() - start
    wave = po.Illumination.plane_wave(scene.source.frequency_hz, scene.source.direction, scene.source.e_hat)

    def stage(offset: float, label: str) -> Progress:
        return lambda name, f: report(f"{label}: {name}", offset + 0.475 * f)

    result_ideal = po.sphere_field(ideal, scene.sphere, wave, spw, device, progress=stage(0.05, "ideal"))
    result_def = po.sphere_field(deformed, scene.sphere, wave, spw, device,
                                 progress=stage(0.525, "deformed"))
    E_ideal, E_def = result_ideal.E, result_def.E
    fringe = {}
    if edges is not None:
        for name, reflector in (("ideal", ideal), ("deformed", deformed)):
            fringe[name] = ptd.sphere_edge_field(reflector, scene.sphere, wave, edges, device=device,
                                                 progress=lambda s, f, n=name: report(f"{n}: {s}", 1.0))
        E_ideal, E_def = E_ideal + fringe["ideal"].E, E_def + fringe["deformed"].E
    if total:
        E_inc = po.incident_field(scene.sphere.points(deformed.F), wave.k, wave.k_hat, wave.e_hat)
        E_inc = E_inc.reshape(E_def.shape)
        E_ideal, E_def = E_ideal + E_inc, E_def + E_inc
    report("done", 1.0)
    seconds = time.perf_counter() - start
    pairs = result_ideal.pairs + result_def.pairs
    radiate_seconds = result_ideal.seconds_radiate + result_def.seconds_radiate
    attrs = {
        **scene_attrs(scene, deformed),
        "field": "total" if total else "scattered",
        "samples_per_wavelength": float(spw),
        "samples": int(result_def.n_samples),
        "samples_lit": int(result_def.n_lit),
        "samples_lit_ideal": int(result_ideal.n_lit),
        "pairs": int(pairs),
        "pair_rate": pairs / radiate_seconds if radiate_seconds > 0 else 0.0,
        "device": str(device or "cpu"),
        "seconds_mesh": mesh_seconds,
        "seconds_total": seconds,
    }
    if edges is not None:
        attrs.update({
            "edges": edges,
            "edge_theory": "Michaeli fringe equivalent edge currents of a half-plane (raysim.optics.ptd)",
            "edge_points_per_wavelength": float(ptd.DEFAULT_POINTS_PER_WAVELENGTH),
            "edge_points": int(fringe["deformed"].n_points),
            "edge_points_lit": int(fringe["deformed"].n_lit),
            "seconds_edges": fringe["ideal"].seconds + fringe["deformed"].seconds,
        })
        layout = deformed.layout
        if edges == "all" and layout is not None and layout.gap > 0:
            attrs["edge_gap_wavelengths"] = layout.gap / wave.wavelength
            attrs["edge_note"] = ("each panel edge is an isolated half-plane: the fringe currents of a "
                                  "gap's two edges add whatever the gap's width, which holds for gaps "
                                  "wider than about a wavelength only")
    extra = {}
    if save_field:
        dims = ("theta", "phi", "component")
        unit = {"units": "1", "reference": "incident plane-wave E amplitude",
                "component": "x, y, z in the reflector frame", "field": attrs["field"]}
        fields = [("E", E_def), ("E_ideal", E_ideal)]
        if edges is not None:  # the edges' share, so that PO alone is E - E_edges
            fields += [("E_edges", fringe["deformed"].E), ("E_edges_ideal", fringe["ideal"].E)]
        for name, E in fields:
            extra[f"{name}_re"] = (dims, E.real, {**unit, "long_name": f"real part of {name}"})
            extra[f"{name}_im"] = (dims, E.imag, {**unit, "long_name": f"imaginary part of {name}"})
    ds = fieldmap(
        scene.sphere, np.sum(np.abs(E_def) ** 2, axis=-1), np.sum(np.abs(E_ideal) ** 2, axis=-1),
        focal_length=deformed.F, diameter=deformed.D, frequency_hz=scene.source.frequency_hz,
        method="po" if edges is None else "po+ptd", sampling="centre", scene=scene.text, attrs=attrs,
        extra=extra,
    )
    if save_field:
        ds = ds.assign_coords(component=("component", ["x", "y", "z"]))
    return ds


def ideal_resolution(scene: Scene) -> float:
    """Triangle edge (m) of the generated mesh, or NaN for a mesh loaded from a file."""
    return float(scene.dish.resolution) if scene.dish.mesh is None else math.nan


def summary(ds: xr.Dataset) -> str:
    """One line: points, rays, time and power balance of a simulated FieldMap."""
    n = ds.sizes["theta"] * ds.sizes["phi"]
    lit = np.isfinite(ds["intensity"].values) & (ds["intensity"].values > 0)
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
