"""One sample's physics in a worker process: what the samples share, kept once per process,
and the intensity of one deformed reflector.

Every sample of a spec traces a twin of the same ideal mesh (same triangulation, vertices
moved along z), on the same sphere grid, under the same wave. So each process keeps, per
spec: the ideal mesh; for GO a :class:`raysim.optics.go.Tracer` (its BVH refitted to each
twin instead of rebuilt, the lattice's tubes and, on axis, their power; on axis over a mesh
whose vertices stand clear of the other faces, no visibility test at all) and the
:class:`~raysim.dataset.memo.VertexFactors` of the deformations at the mesh's vertices. The
ideal intensity itself (any method) is made once per frequency by the run's ideal tasks and
stored; a sample computes its deformed reflector only. None of this changes a number: a
sample is bit for bit what a fresh mesh traced by :func:`raysim.optics.go.trace` gives.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from raysim.dataset.memo import Memo, VertexFactors
from raysim.dataset.spec import DatasetSpec
from raysim.optics import go
from raysim.simulate import go_subdivisions
from raysim.surface.deformation import Deformation
from raysim.surface.mesh import Reflector, paraboloid
from raysim.surface.panels import PanelLayout

Stages = Callable[[str, float], None]  # (stage, seconds it took)
_SETUPS: OrderedDict[tuple[str, str], GOSetup] = OrderedDict()
_IDEALS: OrderedDict[tuple[str, str, int], np.ndarray] = OrderedDict()
_KEEP = 2  # specs whose set-up a process keeps


@lru_cache(maxsize=2)
def ideal_reflector(D: float, F: float, resolution: float, layout: PanelLayout | None) -> Reflector:
    """The ideal generated reflector (D, F, resolution in m; panel layout), kept per process."""
    return paraboloid(D, F, resolution, layout)


def spec_reflector(spec: DatasetSpec) -> Reflector:
    """The ideal reflector of ``spec``'s scene (per process)."""
    dish = spec.scene.dish
    return ideal_reflector(dish.diameter, dish.focal_length, dish.resolution, spec.scene.panels)


@dataclass(frozen=True)
class GOSetup:
    """What the GO samples of one spec share in a process."""

    ideal: Reflector
    tracer: go.Tracer
    factors: VertexFactors


def go_setup(spec: DatasetSpec, device: str = "cpu") -> GOSetup:
    """The per-process GO set-up of ``spec`` (made on first use, the last two kept)."""
    key = (spec.fingerprint, device)
    if key in _SETUPS:
        _SETUPS.move_to_end(key)
        return _SETUPS[key]
    ideal = spec_reflector(spec)
    scene = spec.scene
    tracer = go.Tracer(ideal, scene.sphere, scene.source.direction, go_subdivisions(scene, ideal)[0],
                       device, footprint_shortcut=True)
    setup = GOSetup(ideal, tracer, VertexFactors(ideal.vertices[:, 0], ideal.vertices[:, 1]))
    _SETUPS[key] = setup
    while len(_SETUPS) > _KEEP:
        _SETUPS.popitem(last=False)
    return setup


def intensity(spec: DatasetSpec, deformation: Deformation | None, f_index: int,
              device: str = "cpu", stages: Stages | None = None) -> np.ndarray:
    """Intensity on the spec's sphere grid, (n_theta, n_phi), relative to the incident wave.

    ``deformation`` None gives the ideal paraboloid. ``stages``, if given, hears the seconds
    of each step (``deform``, and GO's ``bvh``, ``visibility``, ``surface``, ``reflect``,
    ``deposit``; or ``wave`` for the other methods).
    """
    report = stages or (lambda stage, seconds: None)
    scene = spec.scene.with_overrides(frequency_hz=spec.frequencies[f_index])
    start = time.perf_counter()
    if spec.method == "go":
        setup = go_setup(spec, device)
        reflector = setup.ideal if deformation is None \
            else setup.ideal.deformed(Memo(deformation, setup.factors))
        report("deform", time.perf_counter() - start)
        return setup.tracer.trace(reflector, _stage_timer(report), scene.probe,
                                  scene.source.e_hat).intensity
    ideal = spec_reflector(spec)
    reflector = ideal if deformation is None else ideal.deformed(Memo(deformation))
    report("deform", time.perf_counter() - start)
    start = time.perf_counter()
    values = wave_intensity(scene, reflector, spec.method, device, spec.radiator, spec.radiator_tol)
    report("wave", time.perf_counter() - start)
    return values


def ideal_intensity(spec: DatasetSpec, f_index: int, device: str = "cpu") -> np.ndarray:
    """The ideal paraboloid's intensity at frequency ``f_index``, once per process (the same
    array every call: do not write into it)."""
    key = (spec.fingerprint, device, int(f_index))
    if key not in _IDEALS:
        _IDEALS[key] = intensity(spec, None, f_index, device)
        _IDEALS[key].flags.writeable = False
        while len(_IDEALS) > 4 * _KEEP:
            _IDEALS.popitem(last=False)
    return _IDEALS[key]


def wave_intensity(scene, reflector: Reflector, method: str, device: str = "cpu", radiator: str = "fast",
                   tol: float = 1e-6) -> np.ndarray:
    """|E|^2 of ``reflector`` on the scene's sphere by PO (``po``), PO plus the rim's fringe
    field (``po+ptd``) or the geometric wave plus every free edge's diffraction (``go+edge``),
    the scattered field at the cell centres as ``raysim.simulate`` gives it (what the scene's
    probe reads of it, :func:`raysim.simulate.probe_power`); ``radiator``, ``tol``: PO's and
    PTD's sums (:func:`raysim.optics.fast.radiator.make_radiator`)."""
    from raysim.optics import goedge, po, ptd
    from raysim.simulate import probe_power

    source = scene.source
    wave = po.Illumination.plane_wave(source.frequency_hz, source.direction, source.e_hat)
    if method == "go+edge":
        E = goedge.sphere_field(reflector, scene.sphere, wave, None, scene.subdivisions or 1,
                                device=device).E
    elif method in ("po", "po+ptd"):
        E = po.sphere_field(reflector, scene.sphere, wave, po.DEFAULT_SAMPLES_PER_WAVELENGTH,
                            device, radiator=radiator, tol=tol).E
        if method == "po+ptd":
            E = E + ptd.sphere_edge_field(reflector, scene.sphere, wave, "rim", device=device,
                                          radiator=radiator, tol=tol).E
    else:  # a method added to raysim.methods needs its branch here
        raise ValueError(f"no wave engine for method {method!r}")
    return probe_power(scene, E)


def _stage_timer(report: Stages) -> go.Progress:
    """A GO progress callback that reports each stage's seconds when the next one starts."""
    last: list = [None, time.perf_counter()]

    def progress(stage: str, fraction: float) -> None:
        now = time.perf_counter()
        if last[0] is not None and last[0] != "lattice":
            report(str(last[0]), now - last[1])
        last[0], last[1] = stage, now

    return progress


def simulate_sample(spec: DatasetSpec, deformation: Deformation, f_index: int,
                    device: str = "cpu", stages: Stages | None = None) -> np.ndarray:
    """The deformed reflector's intensity of one sample, checked to be finite and lit."""
    values = intensity(spec, deformation, f_index, device, stages)
    if not np.all(np.isfinite(values)):
        raise ValueError("the simulated intensity holds non-finite values")
    if not np.any(values > 0):
        raise ValueError("no power reached the sphere")
    return values
