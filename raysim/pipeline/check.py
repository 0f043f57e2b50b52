"""``raysim check``: does the GO assumption hold for this dish, at these frequencies, with these gaps?

For each frequency the dish (a scene, or a mesh file fitted to its paraboloid) is simulated with
GO and with PO + PTD wherever its samples fit the memory, go+edge beyond
(:func:`raysim.pipeline.check_inputs.choose_wave`; the time expected is said first), both with
the same deformation (the scene's, or a realistic mix of gravity-like astigmatism and
actuator bumps, 100 um RMS by default). Then:

- the ideal intensity's and FA's difference GO - wave, over the usable sphere (theta up to the
  rim image minus 2 deg) and per 10 deg theta band (:mod:`raysim.pipeline.check_measures`);
- the surface error the GO assumption costs: the wave data inverted with the GO model (the
  solver's GO refinement), against GO's own data inverted the same way (the baseline), and the
  wave data inverted with the wave-aware refinement (the data's own model by default) to show
  what it recovers; RMS over the aperture and RRMS = RMS / peak-to-peak (docs/inversion.md);
- the panel gaps' signature: GO's dark gap lines against the wave data's dips there.

Everything lands in one ``xarray.Dataset`` (``check.nc``: dims frequency, theta, phi, band, y, x);
the verdict is in words (:func:`verdict_lines`) and numbers (:func:`summary_rows`). Lengths in m,
frequencies in Hz, angles in rad inside; the text quotes um, GHz and deg.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import xarray as xr

from raysim.optics.fast import DEFAULT_TOL
from raysim.pipeline import check_inputs as inputs
from raysim.pipeline.check_inputs import CheckError
from raysim.pipeline.check_measures import (
    bands,
    gap_signature,
    rms_ratio,
    usable,
)
from raysim.pipeline.check_verdict import INVERSIONS, summary_rows, verdict_lines
from raysim.progress import Progress, silent, within
from raysim.render.data import fa
from raysim.version import VERSION_ATTR, __version__

CHECK_FILES = ("check.html", "check.nc", "figures")
REFINE_MODELS = ("auto", "go+edge", "po", "po+ptd", "none")


def check(source: str | os.PathLike[str], *, frequencies: list[float] | None = None,
          deformation: str = "auto", rms: float = inputs.DEFAULT_RMS_M, seed: int = 0,
          gap_m: float | None = None, wave: str = "auto", grid: tuple[int, int] | None = None,
          N: int = 256, refine: int = 3, refine_model: str = "auto", device: str = "cpu",
          sphere_radius: float | None = None, focal_length: float | None = None,
          resolution: float | None = None, progress: Progress | None = None,
          radiator: str = "fast", radiator_tol: float = DEFAULT_TOL,
          mesh_unit: float | None = None, notice: Callable[[str], None] | None = None) -> xr.Dataset:
    """Compare GO with a wave engine on ``source`` at each frequency; return the check dataset.

    Parameters
    ----------
    source : a scene TOML file (or a shipped example's name), or a mesh file (STL, PLY, OBJ,
        GLB) of the dish, fitted to its paraboloid (``focal_length`` m fixes F;
        ``sphere_radius`` m sets the probe sphere, default 0.3 F; ``mesh_unit`` is metres per
        file unit, default 1, 0.001 for a file in millimetres).
    frequencies : Hz; None: the scene's (a mesh needs them).
    deformation : ``auto`` (the scene's when it has one, else the mix), ``scene`` or ``mix``
        (gravity-like astigmatism plus actuator bumps of ``rms`` m RMS, drawn from ``seed``).
    gap_m : panel gap (m) for a generated dish: its layout, or 8 rings of 6 .. 48 panels.
    wave : ``auto`` (the rule of :mod:`raysim.pipeline.check_inputs`) or a method to force.
    grid : sphere cells (n_theta, n_phi); None: the scene's.
    N, refine : the inversions' aperture grid and refinement iterations.
    refine_model : model of the wave-aware refinement: ``auto`` (the data's own), ``go+edge``,
        ``po``, ``po+ptd`` or ``none`` (not run).
    device : Warp device (``cpu``, ``cuda``) for every engine and model.
    resolution : GO triangle edge (m) of a generated dish (default the scene's); on a mesh
        file the GO rays' spacing on its faces (default 0.15 m).
    progress : ``progress(stage, fraction)``, over the whole check.
    radiator, radiator_tol : how PO + PTD sum their elements' fields, in the wave engine, the
        wave models of the inversions and the engine rule's cost (``fast`` or ``direct``; as
        :func:`raysim.simulate`).
    notice : called with one line per frequency, before the first simulation: the wave engine,
        why, and the time the frequency is expected to take (:func:`expected_line`).
    """
    from solver.options import check_options

    say = progress or silent
    check_options(N=N, refine=refine, radiator=radiator, radiator_tol=radiator_tol)
    if refine_model not in REFINE_MODELS:
        raise CheckError(f"unknown --refine-model {refine_model!r}: use one of {', '.join(REFINE_MODELS)}")
    dish = inputs.load_dish(source, sphere_radius=sphere_radius, focal_length=focal_length,
                            resolution=resolution, mesh_unit=mesh_unit)
    freqs = inputs.frequencies_of(dish, frequencies)
    dish = inputs.with_gap(inputs.with_grid(dish, grid), gap_m)
    dish, truth, described = inputs.choose_deformation(dish, deformation, rms, seed)
    if dish.is_mesh:  # the data hold the mesh's own departure from its paraboloid too
        from solver.invert import mesh_truth

        truth = mesh_truth(dish.go) or truth
        described += (f", on the mesh's own departure from its paraboloid "
                      f"({dish.fit_rms * 1e6:.3g} um RMS)")
    engines = [inputs.choose_wave(dish, f, wave, device, radiator) for f in freqs]
    _check_runs(dish, freqs, engines, device)
    for f, engine in zip(freqs, engines, strict=True):
        (notice or _quiet)(expected_line(f, engine, refine, refine_model))
    results = []
    for k, f in enumerate(freqs):
        part = within(say, k / len(freqs), (k + 1) / len(freqs), f"{f / 1e9:g} GHz")
        results.append(_one_frequency(dish, f, engines[k], truth, N, refine, refine_model,
                                      device, part, (radiator, radiator_tol)))
    say("done", 1.0)
    return _dataset(dish, freqs, results, described, source)


def _check_runs(dish: inputs.Dish, freqs, engines, device: str) -> None:
    """Every engine's own checks, before the first simulation."""
    from raysim.simulate import check_options as check_simulation

    for f, engine in zip(freqs, engines, strict=True):
        check_simulation(dish.go.with_overrides(f), method="go", device=device)
        check_simulation(dish.wave.with_overrides(f), method=engine.method, device=device)


#: the time of one forward run of a PO or PO + PTD refinement's model, per time of the wave data
#: (both reflectors): its one reflector on the model's own quadrature (5 m faces) and the
#: solver's work around it; a check of the paper's dish with 3 iterations (5 runs) refined in
#: 3.3, 3.9 and 4.1 times the data's time at 1, 3 and 12 GHz
REFINE_RUN_SHARE = 0.8


def expected_line(f: float, engine: inputs.Engine, refine: int, refine_model: str) -> str:
    """One line on what the check runs at ``f`` Hz and how long it should take: the wave data,
    and the wave-aware refinement where its model is PO or PO + PTD (``refine`` + 2 forward
    runs, :func:`solver.nonlinear.refine`, each :data:`REFINE_RUN_SHARE` of the data's time)."""
    model = engine.method if refine_model == "auto" else refine_model
    if math.isnan(engine.seconds):
        return f"{f / 1e9:g} GHz: {engine.method}. {engine.why}"
    total, refined = engine.seconds, ""
    if model in ("po", "po+ptd") and refine > 0:
        total += engine.seconds * REFINE_RUN_SHARE * (refine + 2)
        refined = f" with its {model} refinement ({refine} iteration{'s' if refine > 1 else ''})"
    return (f"{f / 1e9:g} GHz: {engine.method}, expected to take about {inputs.duration(total)}"
            f"{refined}. {engine.why}")


def _quiet(line: str) -> None:
    """A notice nobody asked for."""


def _one_frequency(dish: inputs.Dish, f: float, engine: inputs.Engine, truth, N: int, refine: int,
                   refine_model: str, device: str, say: Progress,
                   radiator: tuple[str, float] = ("fast", DEFAULT_TOL)) -> dict:
    """GO and the wave engine at ``f``, the maps' differences, the three inversions;
    ``radiator``: (name, tolerance) of the wave engine's and the wave models' sums."""
    from raysim.simulate import simulate

    method, why = engine.method, engine.why
    seconds: dict[str, float] = {}
    start = time.perf_counter()
    go = simulate(dish.go.with_overrides(f), method="go", device=device,
                  progress=within(say, 0.0, 0.1, "GO"))
    seconds["go"] = time.perf_counter() - start
    start = time.perf_counter()
    wave = simulate(dish.wave.with_overrides(f), method=method, device=device,
                    progress=within(say, 0.1, 0.55, method), radiator=radiator[0],
                    radiator_tol=radiator[1])
    seconds["wave"] = time.perf_counter() - start
    sphere = dish.go.sphere
    use = usable(sphere, dish.D, dish.F)[:, None] & np.ones((1, sphere.n_phi), bool)
    maps = {"ideal_go": go["intensity_ideal"].values, "ideal_wave": wave["intensity_ideal"].values,
            "deformed_go": go["intensity"].values, "deformed_wave": wave["intensity"].values,
            "fa_go": fa(go), "fa_wave": fa(wave)}
    out = {"method": method, "why": why, "maps": maps, "seconds": seconds,
           "ideal_difference": rms_ratio(maps["ideal_go"], maps["ideal_wave"], use),
           "fa_difference": rms_ratio(maps["fa_go"], maps["fa_wave"], use),
           "bands": bands(sphere, dish.D, dish.F, maps),
           "gaps": gap_signature(sphere, dish.D, dish.F, maps["ideal_go"], maps["ideal_wave"])}
    model = (method if refine_model == "auto" else refine_model)
    runs = {"go_data": (go, "go"), "go_model": (wave, "go"), "wave_model": (wave, model)}
    out["surfaces"], out["models"] = {}, {}
    for i, (name, (field, model_name)) in enumerate(runs.items()):
        if model_name == "none":
            continue
        lo = 0.55 + 0.15 * i
        say(f"inverting ({name.replace('_', ' ')})", lo)
        start = time.perf_counter()
        out["surfaces"][name] = _invert(field, model_name, truth, N, refine, device, radiator,
                                        within(say, lo, lo + 0.15, f"inverting ({name})"))
        seconds[f"invert_{name}"] = time.perf_counter() - start
        out["models"][name] = model_name
    return out


def _invert(field: xr.Dataset, model: str, truth, N: int, refine: int, device: str,
            radiator: tuple[str, float], say: Progress) -> xr.Dataset:
    from solver.invert import invert

    return invert(field, N=N, refine_iterations=refine, model=model, truth=truth, device=device,
                  progress=say, radiator=radiator[0], radiator_tol=radiator[1])


# --- the dataset ---------------------------------------------------------------------------
SCALARS = {
    "ideal_difference": ("1", "RMS(I_GO - I_wave) / RMS(I_wave), ideal reflector, usable cells"),
    "fa_difference": ("1", "RMS(FA_GO - FA_wave) / RMS(FA_wave), usable cells"),
}


def _dataset(dish: inputs.Dish, freqs, results: list[dict], described: str, source) -> xr.Dataset:
    """The check's numbers and maps (see the module docstring) as one Dataset."""
    sphere = dish.go.sphere
    dims3 = ("frequency", "theta", "phi")
    data: dict = {}
    for key in ("ideal_go", "ideal_wave", "deformed_go", "deformed_wave", "fa_go", "fa_wave"):
        data[f"{'intensity_' if not key.startswith('fa') else ''}{key}"] = (
            dims3, np.stack([r["maps"][key] for r in results]),
            {"units": "1", "long_name": _map_name(key)})
    data["fa_difference_map"] = (dims3, data["fa_go"][1] - data["fa_wave"][1],
                                 {"units": "1", "long_name": "FA_GO - FA_wave"})
    data["gap_dark"] = (dims3, np.stack([r["gaps"].dark for r in results]).astype(np.int8),
                        {"units": "1", "long_name": "1 where GO's ideal map is darkened by a gap"})
    for key, (unit, text) in SCALARS.items():
        data[key] = ("frequency", [r[key] for r in results], {"units": unit, "long_name": text})
    data["wave_method"] = ("frequency", [r["method"] for r in results], {"long_name": "wave engine"})
    data["wave_reason"] = ("frequency", [r["why"] for r in results], {"long_name": "why that engine"})
    b0 = results[0]["bands"]
    for key, text in (("fa_rms", "RMS of FA_wave in the band"),
                      ("fa_difference", "RMS(FA_GO - FA_wave) / RMS(FA_wave) in the band"),
                      ("ideal_difference", "RMS(I_GO - I_wave) / RMS(I_wave) in the band")):
        data[f"band_{key}"] = (("frequency", "band"), np.stack([getattr(r["bands"], key) for r in results]),
                               {"units": "1", "long_name": text})
    for key, text in (("dark_cells", "usable cells GO darkens (gap lines)"),
                      ("usable_cells", "usable cells (theta <= rim image - 2 deg)"),
                      ("go_dip", "GO: mean I / row median - 1 on the dark cells"),
                      ("wave_dip", "wave: mean I / row median - 1 on GO's dark cells"),
                      ("wave_dip_elsewhere", "wave: mean |I / row median - 1| off the dark cells")):
        data[f"gap_{key}"] = ("frequency", [getattr(r["gaps"], key) for r in results],
                              {"units": "1", "long_name": text})
    for step in ("go", "wave", *(f"invert_{n}" for n in INVERSIONS)):
        data[f"seconds_{step}"] = ("frequency", [r["seconds"].get(step, math.nan) for r in results],
                                   {"units": "s", "long_name": f"time of the step {step}"})
    coords = {"frequency": ("frequency", np.asarray(freqs), {"units": "Hz"}),
              "theta": ("theta", sphere.theta, {"units": "rad"}),
              "phi": ("phi", sphere.phi, {"units": "rad"}),
              "band_lo": ("band", b0.lo, {"units": "rad"}), "band_hi": ("band", b0.hi, {"units": "rad"})}
    ds = xr.Dataset(data, coords=coords)
    ds = _with_surfaces(ds, results)
    ds.attrs.update({
        "source": str(source), "dish_notes": " | ".join(dish.notes), "dish_warning": dish.warning,
        "diameter": dish.D,
        "focal_length": dish.F, "sphere_radius": sphere.radius, "deformation": described,
        "gap": inputs.gap_width(dish), "is_mesh": int(dish.is_mesh), "mesh_fit_rms": dish.fit_rms,
        "mesh_pieces": dish.pieces,
        "scene": dish.go.text or "", "usable_theta_max": float(b0.hi[-1]) if len(b0.hi) else math.nan,
        "rule": inputs.ENGINE_RULE, VERSION_ATTR: __version__,
    })
    return ds


def _map_name(key: str) -> str:
    kind, engine = key.split("_")
    what = {"ideal": "intensity of the ideal reflector", "deformed": "intensity of the deformed reflector",
            "fa": "FA = I_ideal / I_def - 1"}[kind]
    return f"{what}, {'GO' if engine == 'go' else 'wave engine'}"


def _with_surfaces(ds: xr.Dataset, results: list[dict]) -> xr.Dataset:
    """Add the truth and each inversion's maps (frequency, y, x), RMS, RRMS and cost."""
    first = next((s for r in results for s in r["surfaces"].values()), None)
    if first is None:
        return ds
    ds = ds.assign_coords(x=("x", first["x"].values, {"units": "m"}),
                          y=("y", first["y"].values, {"units": "m"}))
    if "truth" in first:
        truth = first["truth"].values
        ds["truth"] = (("y", "x"), truth, {"units": "m", "long_name": "deformation tested"})
        ds.attrs["truth_rms"] = float(np.sqrt(np.nanmean(truth**2)))
        ds.attrs["truth_peak_to_peak"] = float(np.nanmax(truth) - np.nanmin(truth))
    nan_map = np.full(first["deformation"].shape, np.nan)
    for name in INVERSIONS:
        surfaces = [r["surfaces"].get(name) for r in results]
        if all(s is None for s in surfaces):
            continue
        label = LABELS[name]
        for key, text in (("deformation", "recovered"), ("error", "recovered - truth")):
            stack = np.stack([s[key].values if s is not None and key in s else nan_map for s in surfaces])
            ds[f"{key}_{name}"] = (("frequency", "y", "x"), stack,
                                   {"units": "m", "long_name": f"{text}: {label}"})
        if name != "go_data" and "deformation_go_data" in ds:
            diff = ds[f"deformation_{name}"].values - ds["deformation_go_data"].values
            ds[f"cost_{name}"] = ("frequency", np.sqrt(np.nanmean(diff**2, axis=(1, 2))),
                                  {"units": "m", "long_name": f"RMS of ({label}) - (GO data, GO "
                                   "refinement): what the physics GO lacks costs"})
        for attr, unit in (("rms_m", "m"), ("rrms", "1")):
            values = [float(s.attrs.get(attr, math.nan)) if s is not None else math.nan for s in surfaces]
            ds[f"{attr.removesuffix('_m')}_{name}"] = ("frequency", values,
                                                       {"units": unit, "long_name": label})
        ds[f"model_{name}"] = ("frequency", [r["models"].get(name, "") for r in results])
    return ds


LABELS = {"go_data": "GO data, GO refinement (baseline)", "go_model": "wave data, GO refinement",
          "wave_model": "wave data, wave-aware refinement"}


# --- the outputs ---------------------------------------------------------------------------
def write_check(source: str | os.PathLike[str], out_dir: str | os.PathLike[str],
                **options) -> tuple[Path, xr.Dataset]:
    """Run :func:`check` and write ``out_dir/check.nc`` and ``out_dir/check.html`` (figures in
    ``figures/``), built in a folder beside ``out_dir`` that replaces an earlier check only when
    complete; a folder holding other files, or holding an input, is refused before any work.
    Returns (path of check.html, the dataset)."""
    from raysim.pipeline.check_page import write_page
    from raysim.pipeline.report import output_folder, staging

    target = output_folder(out_dir, source_inputs(source), CHECK_FILES, "a raysim check", "check.html")
    ds = check(source, **options)
    with staging(target) as out:
        save(ds, out / "check.nc")
        write_page(ds, out)
    return target / "check.html", ds


def source_inputs(source) -> list[tuple[str, Path]]:
    """(what, path) of the files a check reads, for the output checks."""
    from raysim.files import find_input

    path = find_input(source)
    found = [("input", path)]
    if not inputs.is_mesh(path) and path.is_file():
        from raysim.scene.scene import load_scene

        found += load_scene(path).inputs()
    return found


def save(ds: xr.Dataset, path: str | os.PathLike[str]) -> Path:
    """Write the check dataset to NetCDF (atomically: a temporary file renamed)."""
    from raysim.files import atomic_path

    path = Path(path)
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp)
    return path


__all__ = ["CheckError", "check", "save", "source_inputs", "summary_rows", "verdict_lines", "write_check"]
