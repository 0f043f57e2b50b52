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

from raysim import go
from raysim.errors import RaysimError
from raysim.field import fieldmap
from raysim.geometry import reflectors_for
from raysim.scene import Scene

METHODS = ("go", "po", "po+ptd")
Progress = Callable[[str, float], None]


def simulate(scene: Scene, method: str = "go", device: str | None = "cpu",
             progress: Progress | None = None) -> xr.Dataset:
    """Simulate ``scene`` and return its FieldMap (an ``xarray.Dataset``; see raysim.field).

    Parameters
    ----------
    scene : a validated scene (``raysim.load_scene``).
    method : ``go`` (geometric optics); ``po`` and ``po+ptd`` where those engines exist.
    device : ``cpu`` or ``cuda`` (Warp device).
    progress : optional callback (stage name, fraction done in 0..1).
    """
    if method not in METHODS:
        raise RaysimError(f"unknown method {method!r}: use one of {', '.join(METHODS)}")
    report = progress or (lambda stage, fraction: None)
    if method != "go":
        raise RaysimError(f"method {method!r} is not available yet in this version")
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
        "scene_name": scene.name,
        "deformation": scene.deformation.describe(),
        "incidence_theta": scene.source.incidence_theta,
        "incidence_phi": scene.source.incidence_phi,
        "polarization": scene.source.polarization,
        "mesh_resolution": ideal_resolution(scene),
        "mesh_faces": len(deformed.faces),
        "panels": int(deformed.n_panels),
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


def ideal_resolution(scene: Scene) -> float:
    """Triangle edge (m) of the generated mesh, or NaN for a mesh loaded from a file."""
    return float(scene.dish.resolution) if scene.dish.mesh is None else math.nan


def summary(ds: xr.Dataset) -> str:
    """One line: points, rays, time and power balance of a simulated FieldMap."""
    n = ds.sizes["theta"] * ds.sizes["phi"]
    lit = np.isfinite(ds["intensity"].values) & (ds["intensity"].values > 0)
    return (f"{n} points ({int(lit.sum())} lit), {ds.attrs.get('rays', 0):,} rays, "
            f"{ds.attrs.get('seconds_total', float('nan')):.1f} s, power balance "
            f"{ds.attrs.get('power_balance', float('nan')):+.1e} (ideal "
            f"{ds.attrs.get('power_balance_ideal', float('nan')):+.1e})")
