"""File in, files out: what ``raysim correct`` does (see :mod:`solver.correction`).

Reads a SurfaceMap, takes the panel layout from a scene (given, or the one the SurfaceMap's
source FieldMap records), builds or reads the actuators, computes the commands and writes in
the output folder: ``commands.csv`` and ``commands.toml`` (one row per actuator, in the chosen
unit, a header saying what a positive number does and the RMS before and after, and the run's
warnings: the crew loading the commands must see them),
``residual.nc`` (the predicted surface after the correction, a SurfaceMap), ``zernike.csv``
(Noll content of the map and of the residual) and ``summary.txt``. Files are written through a
temporary name and renamed; nothing is written when an input is bad, and an output name that is
a file the run reads (the SurfaceMap, the scene and the files it names, the actuator file, the
source FieldMap) is refused. The commands files carry the stroke ranges (m) when the run had
them, so that they read back as the same actuator file. The Ruze efficiencies take the RMS of
the half-path-length error (:func:`solver.correction.half_path_rms`, F from the SurfaceMap or
the scene).
"""

from __future__ import annotations

import csv
import io
import json
import math
import numbers
import os
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from raysim.errors import RaysimError, SceneError, SurfaceMapError
from raysim.files import write_together
from raysim.maps.surfacemap import HARMONIC_UNOBSERVABLE, NOISE_DRAWS
from raysim.scene.scene import check_frequency
from solver import surface
from solver.actuators import DEFAULT_SCREWS, ActuatorLayout, corners_layout, read_actuators, screws_layout
from solver.correction import Correction, correct, ruze, zernike_fit
from solver.errors import SolverError
from solver.fit import parse_terms

OUTPUTS = ("commands.csv", "commands.toml", "zernike.csv", "summary.txt", "residual.nc")
UNITS = {"um": 1e-6, "mm": 1e-3, "mil": 25.4e-6}
#: decimals of the commands and their std in each unit: 1e-4 um or finer (0.1 nm, 0.025 nm)
DECIMALS = {"um": 4, "mm": 7, "mil": 6}
#: an RMS (m) below this is round-off: a flat map, nothing to correct
FLAT_M = 1e-12
SIGN = ("a positive command moves the surface at the actuator along +z (away from the vertex, "
        "toward the focus) by that many {unit}; the actuator moves by minus the measured error")


@dataclass
class CorrectionRun:
    """What a run produced: the correction, the actuators, the unit and the tables written."""

    correction: Correction
    actuators: ActuatorLayout
    unit: str
    frequencies: tuple[float, ...]
    efficiency_before: np.ndarray
    efficiency_after: np.ndarray
    zernike_before: list
    zernike_after: list
    files: list[Path]
    focal_length: float | None = None
    #: what the commands' std came from (the summary's words)
    std_source: str = "std"


def scene_for(surface_map, scene_path: str | os.PathLike[str] | None, source: str):
    """(scene, source FieldMap path): the scene at ``scene_path``, or the one the SurfaceMap's
    source FieldMap records (a relative source path is read from the SurfaceMap's own folder,
    ``source``'s); either may be None."""
    from raysim.scene.scene import load_scene, scene_of

    src = source_fieldmap(surface_map, source)
    if scene_path is not None:
        return load_scene(scene_path), src
    if src is None:
        return None, None
    from raysim.maps.fieldmap import load as load_fieldmap

    return scene_of(load_fieldmap(src)), src


def layout_for(surface_map, scene, source: str):
    """The panel layout of ``scene`` (see :func:`scene_for`); the scene's dish must be the
    map's: the same diameter (m)."""
    if scene is None or scene.panels is None:
        raise RaysimError(f"{source}: no panel layout (give --scene with a [panels] table, or a "
                          "SurfaceMap whose source FieldMap records one); per-panel commands need it")
    D = float(surface_map.attrs["diameter"])
    rim = 2.0 * scene.panels.rim_radius
    if not math.isclose(rim, D, rel_tol=1e-6):
        raise RaysimError(f"{source}: the map is of a {D:g} m dish, the panel layout of a {rim:g} m "
                          "one; give the scene of the dish that was measured")
    return scene.panels


def focal_length_for(surface_map, scene) -> tuple[float | None, str]:
    """The dish's focal length (m) for the half-path-length error: the SurfaceMap's
    ``focal_length`` attribute, else the scene's; (None, a note) when neither knows it."""
    try:
        F = float(surface_map.attrs.get("focal_length", math.nan))
    except (TypeError, ValueError):
        F = math.nan
    if math.isfinite(F) and F > 0:
        return F, ""
    if scene is not None and scene.dish.focal_length is not None:
        return float(scene.dish.focal_length), ""
    return None, ("the SurfaceMap records no focal_length and no scene gives one: the Ruze "
                  "efficiencies use the axial RMS, not the half-path-length error")


def input_paths(surface_path, scene, scene_path, actuators, fieldmap) -> dict[Path, str]:
    """Every file the run reads, resolved, with what it is: the SurfaceMap, the scene and the
    files it names (deformation maps, meshes), the actuator file and the source FieldMap."""
    named = [(surface_path, "the SurfaceMap"), (scene_path, "the scene"),
             (actuators, "the actuator file"), (fieldmap, "the SurfaceMap's source FieldMap")]
    if scene is not None:
        named += [(p, f"{what} ({scene.name})") for what, p in scene.inputs()]
    return {Path(p).resolve(): what for p, what in named if p is not None}


def check_outputs(out: Path, inputs: dict[Path, str]) -> None:
    """Refuse an output name that is one of the ``inputs`` (or a folder): writing it would
    destroy what the run reads."""
    for name in OUTPUTS:
        target = (out / name).resolve()
        same = [what for p, what in inputs.items()
                if p == target or (target.exists() and p.exists() and os.path.samefile(p, target))]
        if same:
            raise SolverError(f"{out / name}: is an input ({same[0]}); write the correction to "
                              "another folder")
        if (out / name).is_dir():
            raise SolverError(f"{out / name}: is a folder; write the correction to another folder")


def source_fieldmap(surface_map, source: str) -> Path | None:
    """The FieldMap a SurfaceMap was inverted from, when it records one that exists: an absolute
    path as it is, a relative one from the SurfaceMap's folder."""
    src = str(surface_map.attrs.get("source_fieldmap", "") or "")
    if not src:
        return None
    path = Path(src).expanduser()
    if not path.is_absolute():
        path = Path(source).parent / path
    return path if path.is_file() else None


def actuators_for(layout, kind: str | None, path: str | os.PathLike[str] | None,
                  screws: tuple[tuple[float, float], ...] = DEFAULT_SCREWS) -> ActuatorLayout:
    if path is not None:
        return read_actuators(path, layout)
    if kind in (None, "corners"):
        return corners_layout(layout)
    if kind == "screws":
        return screws_layout(layout, screws)
    raise SolverError(f"unknown --layout {kind!r}: choose corners or screws")


def run_correct(surface_path, outdir, *, scene=None, actuators=None, layout_kind=None,
                remove: str | None = "piston,tilt", unit: str = "um", frequencies=(),
                zernike_order: int = 4, screws=DEFAULT_SCREWS,
                stroke: float | None = None) -> CorrectionRun:
    """Correct the SurfaceMap at ``surface_path`` and write the files in ``outdir`` (see the
    module). ``stroke`` (m) bounds every generated actuator to [-stroke, stroke]."""
    if unit not in UNITS:
        raise SolverError(f"unknown --unit {unit!r}: choose {', '.join(UNITS)}")
    if (isinstance(zernike_order, bool) or not isinstance(zernike_order, numbers.Integral)
            or not 0 <= zernike_order <= 20):
        raise SolverError(f"--zernike-order must be an integer in 0..20, got {zernike_order!r}")
    try:
        freqs = tuple(float(f) for f in np.atleast_1d(np.asarray(frequencies, dtype=np.float64)))
    except (TypeError, ValueError):
        raise SolverError(f"--frequency must be numbers in Hz, got {frequencies!r}") from None
    for f in freqs:  # 43 (GHz meant) gave "Ruze 1.00000 -> 1.00000" without a word
        try:
            check_frequency(f, "--frequency")
        except SceneError as exc:
            raise SolverError(str(exc)) from None
    if stroke is not None and not (stroke > 0 and math.isfinite(stroke)):
        raise SolverError("--stroke must be a finite number > 0")
    if stroke is not None and actuators is not None:
        raise SolverError("--stroke bounds generated layouts; an actuator file gives each "
                          "actuator's range in its min_m and max_m")
    terms = parse_terms(remove)
    out = Path(outdir)
    check_outputs(out, input_paths(surface_path, None, scene, actuators, None))
    smap = surface.load(surface_path)
    if not np.isfinite(smap["deformation"].values).any():
        raise SolverError(f"{surface_path}: the map holds no finite deformation; nothing to correct")
    scene_obj, fieldmap = scene_for(smap, scene, str(surface_path))
    check_outputs(out, input_paths(surface_path, scene_obj, scene, actuators, fieldmap))
    layout = layout_for(smap, scene_obj, str(surface_path))
    acts = actuators_for(layout, layout_kind, actuators, screws)
    if stroke is not None:
        acts = ActuatorLayout(acts.ids, acts.xy, acts.supports,
                              np.tile([-stroke, stroke], (acts.n_actuators, 1)), acts.kind)
    F, f_note = focal_length_for(smap, scene_obj)
    grid = surface.grid_of(smap)
    std = smap["deformation_std"].values if "deformation_std" in smap else None
    draws = smap[NOISE_DRAWS].values if NOISE_DRAWS in smap else None
    try:
        corr = correct(grid, smap["deformation"].values, layout, acts, terms, std, focal_length=F,
                       noise_draws=draws)
    except SurfaceMapError as exc:  # a map in the wrong unit: say which file
        raise SurfaceMapError(f"{surface_path}: {exc}") from None
    if f_note:
        corr.notes.append(f_note)
    corr.notes += map_caveats(smap.attrs, layout.n_panels)
    sigma_before, sigma_after = ruze_sigmas(corr)
    under = ("the stated intensity_std" if smap.attrs.get("noise_source") == "intensity_std"
             else "the noise estimated from the scan")
    source = (f"noise draws ({len(draws)}, the inversion's Monte Carlo under {under})"
              if draws is not None else "std (points taken as independent: a floor for an inverted map)")
    run = CorrectionRun(corr, acts, unit, freqs, ruze(sigma_before, freqs), ruze(sigma_after, freqs),
                        zernike_fit(grid, corr.before, zernike_order),
                        zernike_fit(grid, corr.after, zernike_order), [], F, source)
    header = header_lines(run, terms)
    attrs = {k: v for k, v in smap.attrs.items() if k not in ("rms_m", "rrms")}
    attrs.update(correction="predicted surface after the actuator commands",
                 correction_rms_before_m=corr.rms_before, correction_rms_after_m=corr.rms_after,
                 removed_terms=",".join(terms) or "none", command_sign=SIGN.format(unit=unit))
    # NaN stays NaN: points without data and the gaps between panels are no corrected surface
    residual = surface.surfacemap(grid, corr.after, attrs)
    texts = {"commands.csv": commands_csv(run, header), "commands.toml": commands_toml(run, header),
             "zernike.csv": zernike_csv(run, header),
             "summary.txt": "\n".join([SIGN.format(unit=unit), *summary_lines(run)]) + "\n"}
    # one set: a failure, a full disk or an interrupt leaves the folder's previous files, all of
    # them (a crew must never read commands beside another fit's residual and summary)
    writers: dict[Path, Callable[[Path], object]] = {
        out / name: partial(Path.write_text, data=text, encoding="utf-8") for name, text in texts.items()}
    writers[out / "residual.nc"] = partial(surface.save, residual)
    write_together(writers)
    run.files = [out / n for n in OUTPUTS]
    return run


#: what raysim invert warned of in the map, repeated where the commands are read
MAP_WARNINGS = ("noise_warning", "hole_warning", "ring_warning", "sampling_warning",
                "saturation_warning", "refine_warning")


def map_caveats(attrs, n_panels: int) -> list[str]:
    """What the SurfaceMap's ``attrs`` say the map may not hold, for the commands' summary:
    ``raysim invert``'s warnings, a harmonic part taken as zero on the rim (no rim targets),
    and, for a map from GO data or refined with GO on ``n_panels`` > 1 panels, the panel
    pistons GO does not see. The
    predicted residual is of the map, so it leaves all of these out: a map that is mostly noise
    gave commands that made the dish worse (25 -> 32 um) beside a prediction of 47 -> 16 um."""
    lines = [f"WARNING (the map's, from raysim invert): {attrs[key]}" for key in MAP_WARNINGS
             if key in attrs]
    if lines:
        lines.append("the predicted residual is the map's and leaves out the map's own errors "
                     "warned of above: the dish may end worse than predicted")
    if attrs.get("harmonic_part") == HARMONIC_UNOBSERVABLE:
        lines.append("the map's harmonic part (tilt, astigmatism, any r^n cos n phi) was "
                     "UNOBSERVABLE and taken as zero on the rim (no rim targets): whatever the "
                     "dish has of it is neither corrected nor in the predicted residual; invert "
                     "with --rim targets to include it")
    if "go" in (attrs.get("data_method"), attrs.get("refine_model")) and n_panels > 1:
        lines.append("GO does not see a panel's piston against its neighbours (docs/"
                     "inversion.md): steps between panels are not in a map from GO data or "
                     "refined with GO, so the commands neither correct them nor count them in "
                     "the predicted residual")
    return lines


def ruze_sigmas(c: Correction) -> tuple[float, float]:
    """The RMS (m) before and after that Ruze's law takes: the half-path-length error where the
    focal length was known, else the axial RMS."""
    if c.path_rms_before is None or c.path_rms_after is None:
        return c.rms_before, c.rms_after
    return c.path_rms_before, c.path_rms_after


def header_lines(run: CorrectionRun, terms) -> list[str]:
    c = run.correction
    lines = [SIGN.format(unit=run.unit),
             f"panel shape: {run.actuators.shape_description()}",
             f"terms left to pointing/focus (removed before fitting): {','.join(terms) or 'none'}",
             f"surface RMS before {c.rms_before / 1e-6:.3f} um, predicted after {c.rms_after / 1e-6:.3f} um",
             f"out of reach within the panels (rigid-panel floor) {c.within_panel_rms / 1e-6:.3f} um"]
    if c.path_rms_before is not None and c.path_rms_after is not None:
        lines.append(f"half-path-length error dz / (1 + rho^2 / 4F^2) (Ruze's epsilon, F = "
                     f"{run.focal_length or math.nan:g} m), RMS before {c.path_rms_before / 1e-6:.3f} "
                     f"um, predicted after {c.path_rms_after / 1e-6:.3f} um")
    sigma = "half-path-length" if c.path_rms_before is not None else "axial"
    for f, b, a in zip(run.frequencies, run.efficiency_before, run.efficiency_after, strict=True):
        lines.append(f"Ruze efficiency at {f / 1e9:g} GHz: {b:.5f} before, {a:.5f} after "
                     f"(from the {sigma} RMS)")
    return lines


def _rows(run: CorrectionRun) -> list[dict]:
    """One row per actuator: id, position (m), panels, stroke range (m, when the run had one:
    the files read back as actuator files keep it; '' for an open end) and the command (and
    its std) in the run's unit."""
    scale, places = UNITS[run.unit], DECIMALS[run.unit]
    c, acts = run.correction, run.actuators
    rows = []
    for i, name in enumerate(acts.ids):
        # positions to the micrometre: the files are read back as actuator files
        row = {"id": name, "x_m": f"{acts.xy[i, 0]:.6f}", "y_m": f"{acts.xy[i, 1]:.6f}",
               "panels": " ".join(str(p) for p in acts.panels_of(i))}
        if acts.ranges is not None:
            row["min_m"], row["max_m"] = (repr(float(v)) if math.isfinite(v) else ""
                                          for v in acts.ranges[i])
        row[f"command_{run.unit}"] = f"{c.commands[i] / scale:.{places}f}"
        if c.command_std is not None:
            row[f"command_std_{run.unit}"] = f"{c.command_std[i] / scale:.{places}f}"
        rows.append(row)
    return rows


def warning_lines(run: CorrectionRun) -> list[str]:
    """The run's notes (summary.txt's last lines: what correct warns of and what the map's
    attributes say it may not hold), one line each: a line break in a map's attribute would end
    a CSV comment and start a row of actuators."""
    return [" ".join(str(note).split()) for note in run.correction.notes]


def commands_csv(run: CorrectionRun, header: list[str]) -> str:
    """The commands as CSV: ``header`` and the run's warnings as ``#`` comment lines (those
    the crew loading the commands must see, not only the console), then one row per actuator."""
    buf = io.StringIO()
    for line in header:
        buf.write(f"# {line}\n")
    for line in warning_lines(run):
        buf.write(f"# {line if line.startswith('WARNING') else 'WARNING: ' + line}\n")
    rows = _rows(run)
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def toml_string(text: str) -> str:
    """``text`` as a TOML basic string: JSON's escapes are TOML's; the characters kept as they are
    (JSON's \\u escapes of characters beyond U+FFFF are surrogate pairs, which TOML refuses),
    DEL escaped (TOML refuses it bare)."""
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


def commands_toml(run: CorrectionRun, header: list[str]) -> str:
    """The commands as TOML: ``header`` as comments, ``unit``, the RMS before and after,
    ``warnings`` (the run's warnings, a list of strings; [] when there are none) and one
    ``[[actuator]]`` table per actuator."""
    lines = [f"# {h}" for h in header]
    c = run.correction
    warnings = warning_lines(run)
    lines += [f'unit = "{run.unit}"', f"rms_before_{run.unit} = {c.rms_before / UNITS[run.unit]:.6g}",
              f"rms_after_{run.unit} = {c.rms_after / UNITS[run.unit]:.6g}",
              "warnings = [" + "".join(f"\n    {toml_string(w)}," for w in warnings)
              + ("\n]" if warnings else "]"), ""]
    for row in _rows(run):
        lines.append("[[actuator]]")
        for k, v in row.items():
            if k == "id":
                lines.append(f"id = {json.dumps(v)}")  # a TOML basic string, escapes included
            elif k == "panels":
                lines.append(f"panels = [{', '.join(v.split())}]")
            elif v == "":
                continue  # an open end of a range: no key
            else:
                lines.append(f"{k} = {v}")
        lines.append("")
    return "\n".join(lines)


def zernike_csv(run: CorrectionRun, header: list[str]) -> str:
    buf = io.StringIO()
    buf.write(f"# {header[0]}\n# Noll terms: coefficient = the term's RMS over the disk (um)\n")
    buf.write("noll_j,n,m,map_um,residual_um\n")
    for (j, n, m, b), (_, _, _, a) in zip(run.zernike_before, run.zernike_after, strict=True):
        buf.write(f"{j},{n},{m},{b / 1e-6:.4f},{a / 1e-6:.4f}\n")
    return buf.getvalue()


def _left(c: Correction) -> str:
    """What share of the RMS the correction leaves, in words (a map flat to round-off after the
    removed terms has nothing to correct)."""
    if c.rms_before > FLAT_M:
        return f"{100 * c.rms_after / c.rms_before:.1f} % left"
    return "a flat surface, nothing to correct"


def summary_lines(run: CorrectionRun) -> list[str]:
    """What ``raysim correct`` prints and writes in summary.txt: the actuators, the RMS before
    and after (axial and half-path-length), the commands (in the run's unit), the Ruze
    efficiencies and the notes."""
    c, unit, scale = run.correction, run.unit, UNITS[run.unit]
    lines = [f"{run.actuators.n_actuators} actuators ({run.actuators.kind}); "
             f"{run.actuators.shape_description()}",
             f"RMS {c.rms_before / 1e-6:.2f} um before, {c.rms_after / 1e-6:.2f} um predicted after "
             f"({_left(c)}; rigid-panel floor, out of reach of "
             f"rigid panel motions: {c.within_panel_rms / 1e-6:.2f} um)"]
    if c.path_rms_before is not None and c.path_rms_after is not None:
        lines.append(f"half-path-length error (Ruze's epsilon, F = {run.focal_length or math.nan:g} m): "
                     f"RMS {c.path_rms_before / 1e-6:.2f} um before, {c.path_rms_after / 1e-6:.2f} um after")
    lines.append(f"commands: max |c| {np.max(np.abs(c.commands)) / scale:.{DECIMALS[unit] - 1}f} {unit}"
                 + (f", {c.clipped} at their range limit" if c.clipped else ""))
    if c.command_std is None:
        lines.append("command error: not computed: the map carries no noise draws or std (raysim "
                     "invert keeps them when the scan states intensity_std, or when the noise it "
                     "estimates spreads the map by a tenth of the map's RMS or more)")
    else:
        known = c.command_std[np.isfinite(c.command_std)]
        if known.size:
            med, top = np.median(known) / scale, np.max(known) / scale
            lines.append(f"command error from the map's {run.std_source}: median "
                         f"{med:.{DECIMALS[unit]}f} {unit}, max {top:.{DECIMALS[unit]}f} {unit}")
        if known.size < c.command_std.size:
            lines.append(f"{c.command_std.size - known.size} actuators have points of unknown "
                         "spread (deformation_std NaN) on their panels: their command error is "
                         "unknown (nan)")
    lines += [line for line in header_lines(run, ()) if line.startswith("Ruze")]
    lines += c.notes
    return lines
