"""File in, file out: what ``raysim invert`` does, as one function the command line wraps.

Reads a FieldMap (NetCDF) and optional rim targets (CSV x,y,dz in m), runs
:func:`solver.invert.invert`, writes the SurfaceMap atomically, optionally writes the per-panel
adjustment table, and returns the SurfaceMap with a short human summary.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import xarray as xr

from raysim.errors import RaysimError
from raysim.files import check_output
from raysim.maps.fieldmap import load as load_fieldmap
from raysim.maps.surfacemap import HARMONIC_UNOBSERVABLE
from raysim.progress import Progress
from solver import boundary, surface
from solver.fit import panel_adjustments, write_panel_csv
from solver.gauss_newton import GaussNewtonOptions
from solver.invert import DEFAULT_N, DEFAULT_REFINE, DEFAULT_SOLVER, invert
from solver.record import um_text


def panel_layout_of(field: xr.Dataset):
    """The panel layout of the scene a FieldMap records, or None (a measured scan has none)."""
    from raysim.scene.scene import scene_of

    scene = scene_of(field)
    return None if scene is None else scene.panels


def run_invert(field_path: str | os.PathLike[str], output: str | os.PathLike[str], *,
               solver: str = DEFAULT_SOLVER, N: int = DEFAULT_N,
               rim_csv: str | os.PathLike[str] | None = None, remove: str | None = None,
               refine: int = DEFAULT_REFINE, gain: str = "auto", iterations: int | None = None,
               device: str | None = "cpu",
               panels_csv: str | os.PathLike[str] | None = None, model: str | None = None,
               progress: Progress | None = None, refine_method: str = "defect",
               gauss_newton: GaussNewtonOptions | None = None,
               log: Callable[[str], None] | None = None, radiator: str = "fast",
               radiator_tol: float = 1e-6) -> xr.Dataset:
    """Invert the FieldMap at ``field_path`` and write the SurfaceMap to ``output``.

    Options as :func:`solver.invert.invert`; ``rim_csv`` is a CSV ``x,y,dz`` (m) of rim
    targets; ``panels_csv`` receives the per-panel adjustment table (needs a FieldMap whose
    scene has panels); ``model`` names the refinement's forward model (None: from the data's
    method); ``progress(stage, fraction)`` follows the refinement; ``refine_method``,
    ``gauss_newton`` (its steps and LSQR iterations) and ``log(line)`` (each Gauss-Newton step)
    and ``radiator``, ``radiator_tol`` as :func:`solver.invert.invert`. Nothing is
    written when an input is bad.
    """
    inputs = [("FieldMap", field_path), ("rim-target file", rim_csv)]
    check_output(output, inputs)
    if panels_csv is not None:
        check_output(panels_csv, [*inputs, ("SurfaceMap output", output)])
    field = load_fieldmap(field_path)
    from raysim.scene.scene import recorded_files

    scene_files = recorded_files(field)  # the inversion reads them for the truth: inputs too
    if scene_files:
        inputs += scene_files
        check_output(output, inputs)
        if panels_csv is not None:
            check_output(panels_csv, [*inputs, ("SurfaceMap output", output)])
    rim = boundary.read_rim_csv(rim_csv) if rim_csv is not None else None
    layout = None
    if panels_csv is not None:
        layout = panel_layout_of(field)
        if layout is None:
            raise RaysimError(f"{field_path}: records no panel layout (no scene with [panels]); "
                              "--panels-csv needs one")
    result = invert(field, solver=solver, N=N, rim=rim, remove=remove,
                    refine_iterations=refine, gain=gain, iterations=iterations, device=device,
                    model=model, progress=progress, refine_method=refine_method,
                    gauss_newton=gauss_newton, log=log, radiator=radiator, radiator_tol=radiator_tol)
    result.attrs["source_fieldmap"] = str(Path(field_path).resolve())  # any folder can find it
    surface.save(result, output)
    if layout is not None:
        grid = surface.grid_of(result)
        write_panel_csv(panel_adjustments(grid, result["deformation"].values, layout),
                        Path(panels_csv))
    return result


def _scale(c: float) -> str:
    """A scan's scale as the summary prints it: six decimals near 1, else six significant
    digits (readings in W are 1e-9 of the ideal: "0.000000" told nothing)."""
    return f"{c:.6f}" if 1e-2 <= abs(c) < 1e3 else f"{c:.6g}"


def summary(result: xr.Dataset) -> list[str]:
    """Lines for the user: accuracy (when the truth is known), solver, boundary, time."""
    a = result.attrs
    lines = []
    if "rms_m" in a:
        relative = (f"RRMS {a['rrms'] * 100:.3f} %" if math.isfinite(a["rrms"]) and
                    a["truth_peak_to_peak_m"] > 0 else "RRMS n/a (a flat truth has no peak-to-peak)")
        error = a["rms_m"] * 1e6  # um; a 0.01 um map's error was printed as 0.00 um
        shown = f"{error:.2f}" if error >= 0.01 else f"{error:.2g}"
        lines.append(f"RMS error {shown} um, {relative} "
                     f"(truth peak-to-peak {a['truth_peak_to_peak_m'] * 1e3:.4f} mm)")
    else:
        lines.append("truth unknown: no RMS / RRMS")
    state = "converged" if a.get("solver_converged") else "NOT converged"
    lines.append(f"solver {a['solver']} ({a.get('solver_iterations', 0)} iterations, "
                 f"residual {a.get('solver_residual', 0.0):.1e}, {state}); "
                 f"refinement {a.get('refine_iterations', 0)} iterations, model "
                 f"{a.get('refine_model', 'go')} ({a.get('refine_model_choice', '')}), "
                 f"{a.get('refine_seconds', 0.0):.1f} s")
    stopped = str(a.get("refine_stopped", ""))
    if stopped and not stopped.startswith("no"):
        lines[-1] += f"; stopped early: {stopped}"
    if "refine_warning" in a:
        lines.append(f"WARNING: {a['refine_warning']}")
    if a.get("gn_used"):
        misfit = str(a["gn_misfit_rms"]).split(",")
        lines.append(f"gauss-newton ({a['gn_choice']}): misfit {misfit[0]} -> {misfit[-1]} "
                     f"(noise {a['gn_noise_rms']:.2e}), LSQR {a['gn_lsqr_iterations']}, "
                     f"stopped: {a['gn_stopped']}")
    if "hole_warning" in a:
        lines.append(f"WARNING: {a['hole_warning']}")
    if "ring_warning" in a:
        lines.append(f"WARNING: {a['ring_warning']}")
    if "sampling_warning" in a:
        lines.append(f"WARNING: {a['sampling_warning']}")
    if "saturation_warning" in a:
        lines.append(f"WARNING: {a['saturation_warning']}")
    if a.get("rows_dropped_at_rim"):
        lines.append(f"rim: {a['rows_dropped_why']}")
    lines.append(f"boundary: {a['boundary']}")
    if a["harmonic_part"] == HARMONIC_UNOBSERVABLE:
        lines.append("harmonic part (tilt, astigmatism, any r^n cos n phi) is UNOBSERVABLE "
                     "without rim targets: the map assumes zero on the rim")
    elif int(a.get("rim_harmonic_order", boundary.MAX_HARMONICS)) < 3:  # not even astigmatism
        k = int(a["rim_harmonic_order"])
        lines.append(f"WARNING: the rim targets fix the harmonic part to order {k} only (r^n cos "
                     f"n phi, n <= {k}; their count and widest gap allow no more): higher orders "
                     "are UNOBSERVABLE, assumed zero on the rim")
    if "removed_central_mode_m" in a:
        lines.append(f"blocked centre r < {a['central_hole_radius_m']:.2f} m: its central mode is "
                     f"UNOBSERVABLE and removed (c = {a['removed_central_mode_m'] * 1e6:.2f} um)")
    if a.get("samples_blocked"):
        lines.append(f"{a['samples_blocked']} samples hidden by obstacles: treated as missing")
    if a.get("gain_known", True):
        lines.append(f"gain known ({a['gain_choice']}): scale {_scale(a['gain'])} trusted, delta_c "
                     "kept")
    else:
        spread = (f"+- {a['gain_std']:.1e}" if math.isfinite(a["gain_std"])
                  else "(no standard error: the readings' noise is unknown)")
        lines.append(f"gain ESTIMATED ({a['gain_choice']}): scale {_scale(a['gain'])} {spread}, "
                     f"{100 * a['gain_coverage']:.1f} % of the power "
                     f"scanned; delta_c (the shape a scale error makes) is UNOBSERVABLE and "
                     f"removed: coefficient {a['removed_delta_c']:.3e} (an FA offset), "
                     f"{1e6 * a['removed_delta_c_centre_m']:.2f} um at the centre")
    lines.append(f"removed terms: {a['removed_terms']}; missing samples {a['samples_missing']}")
    kept = "deformation_std" in result and np.any(np.isfinite(result["deformation_std"].values))
    if kept and a.get("noise_source") == "intensity_std":
        std = result["deformation_std"].values
        lines.append(f"noise: the scan's stated intensity_std spreads the map by "
                     f"{np.sqrt(np.nanmean(std**2)) * 1e6:.2f} um RMS (deformation_std, Monte "
                     "Carlo of the linear inversion)")
    elif "noise_map_rms_m" in a:
        db = 10.0 / math.log(10.0) * a["noise_relative_std"]
        lines.append(f"noise: {db:.2g} dB per cell ({a['noise_source']}) spreads the map by "
                     f"{um_text(a['noise_map_rms_m'])} um RMS (Monte Carlo of the linear "
                     "inversion; no intensity_std stated" + ("; deformation_std and its draws "
                                                             "kept" if kept else "") + ")")
    if "noise_warning" in a:
        lines.append(f"WARNING: {a['noise_warning']}")
    lines.append(f"time {a['time_s']:.2f} s")
    return lines
