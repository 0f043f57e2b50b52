"""``raysim report``: scene -> simulate -> invert -> the paper's Figs. 8-10 in one HTML page.

The page (``report.html``) is self-contained: every figure is embedded as a base64 PNG, and the
same PNGs, the FieldMap and the SurfaceMap are written beside it. It states the run's numbers
(RMS and RRMS of the recovered surface, simulation, inversion and drawing times, the solver
and its boundary assumption), what the data cannot determine (in the words ``raysim invert``
prints) and the scene text; for the paper's own case it quotes the paper's figure for the same
kind of data beside ours: its GO case for GO data, its Table 3 row for PO (+ PTD) data at a
frequency Table 3 lists, none otherwise.
"""

from __future__ import annotations

import base64
import contextlib
import html
import io
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import xarray as xr

from raysim.files import write_bytes, write_text
from raysim.maps.surfacemap import HARMONIC_FIXED, HARMONIC_UNOBSERVABLE
from raysim.progress import Progress, silent
from raysim.render import backend, figures
from raysim.render.backend import RenderError
from raysim.render.data import (
    UM,
    error_summary,
    frequency_text,
    method_text,
    peak_to_peak,
    rms,
    surface_panels,
)
from raysim.version import VERSION_ATTR

PAPER_CASE = {"diameter": 110.0, "focal_length": 33.0, "sphere_radius": 10.0}
PAPER_GO = ("GO data (the Table 2 case): FDM (Gauss-Seidel, N = 256, 1000 iterations) RRMS 4.06 % "
            "in 92 ± 10 s; FFT RRMS 7.47 %")
PAPER_PO_METHODS = ("po", "po+ptd")  # the data of the paper's Table 3 (PO & PTD)


REPORT_FILES = ("report.html", "field.nc", "surface.nc", "figures")
PAGE_STYLE = """<style>
body { font-family: sans-serif; max-width: 1500px; margin: 2em auto; padding: 0 1em; color: #222; }
table { border-collapse: collapse; margin: 1em 0; }
th, td { text-align: left; padding: 0.25em 1em; border-bottom: 1px solid #ddd; vertical-align: top; }
figure { margin: 2em 0; }
img { max-width: 100%; height: auto; box-sizing: border-box; border: 1px solid #ccc; }
figcaption { font-size: 0.95em; margin-top: 0.4em; }
pre { background: #f5f5f5; padding: 1em; overflow-x: auto; }
.limits { border-left: 4px solid #c0392b; padding: 0.3em 0 0.3em 0.8em; background: #fdf3f2; }
.warnings { border-left: 4px solid #d35400; padding: 0.3em 0 0.3em 0.8em; background: #fdf2e9; }
.warnings ul { margin: 0.3em 0; }
.overrides { border-left: 4px solid #2c7fb8; padding: 0.3em 0 0.3em 0.8em; background: #f1f6fb; }
</style>"""


def report(source: str | os.PathLike[str], out_dir: str | os.PathLike[str], *, method: str | None = None,
           device: str = "cpu", solver: str | None = None, grid: int | None = None,
           refine: int | None = None, invert: bool = True,
           progress: Progress | None = None) -> Path:
    """Simulate a scene (or take a FieldMap), invert it and write the report into ``out_dir``.

    Every option is checked before the simulation starts. The report is built in a temporary
    folder beside ``out_dir`` and replaces an earlier report there only once it is complete,
    so a failed run leaves the old report as it was; a folder holding other files is refused.

    Parameters
    ----------
    source : scene TOML file (or a shipped example's name), or a FieldMap NetCDF (``.nc``)
        already simulated or measured.
    out_dir : folder for ``report.html``, ``field.nc``, ``surface.nc`` and ``figures/``.
    method : simulation method (``go``, ``po``, ``po+ptd``, ``go+edge``); None takes the scene's ``method``.
    device : Warp device, ``cpu`` or ``cuda``.
    solver, grid, refine : the inversion's Poisson solver, aperture grid points N and GO
        refinement iterations (0: the paper's linear answer); None: the solver's defaults.
    invert : False leaves the inversion out: the field's figures only (8a-d, 9).
    progress : optional ``progress(stage, fraction)`` (:mod:`raysim.progress`), once per stage
        (simulating, inverting, drawing, done).
    Returns the path of ``report.html``.
    """
    from raysim.files import find_input
    from raysim.maps.fieldmap import load, save

    say = progress or silent
    run_inversion = inversion() if invert else None
    if invert:
        from solver.options import check_options

        check_options(solver=solver, N=grid, refine=refine)
    timings: dict[str, float] = {}
    if Path(source).is_dir():
        raise RenderError(f"{source}: is a folder, give a scene file or a FieldMap (.nc)")
    is_field = Path(source).suffix.lower() in (".nc", ".nc4", ".netcdf")
    if is_field:
        field = load(source)
        inputs = [("FieldMap", Path(source))]
    else:
        from raysim.scene.scene import load_scene
        from raysim.simulate import check_options as check_simulation
        from raysim.simulate import simulate

        loaded = load_scene(find_input(source))
        method = method or loaded.method
        check_simulation(loaded, method=method, device=device)
        inputs = loaded.inputs()
    target = _target(out_dir, inputs)
    with staging(target) as out:
        if not is_field:
            say(f"simulating {loaded.name} ({method})", 0.0)
            start = time.perf_counter()
            field = simulate(loaded, method=method, device=device)
            timings["simulate"] = time.perf_counter() - start
            save(field, out / "field.nc")
        surface = None
        if run_inversion is not None:
            say("inverting", 0.6)
            start = time.perf_counter()
            surface = run_inversion(field, solver=solver, grid=grid, refine=refine, device=device)
            timings["invert"] = time.perf_counter() - start
            # the FieldMap it came from (``raysim correct`` finds the panel layout there): the
            # report's own field.nc, read from the SurfaceMap's folder, or the one given
            surface.attrs["source_fieldmap"] = str(Path(source).resolve()) if is_field else "field.nc"
            _save_surface(surface, out / "surface.nc")
        say("drawing", 0.8)
        write_report(field, surface, out, timings=timings)
    say("done", 1.0)
    return target / "report.html"


def _target(out_dir: str | os.PathLike[str], inputs) -> Path:
    """The report folder, checked (:func:`output_folder`)."""
    return output_folder(out_dir, inputs, REPORT_FILES, "a raysim report", "report.html")


def output_folder(out_dir: str | os.PathLike[str], inputs, files: tuple[str, ...], what: str,
                  mark: str) -> Path:
    """An output folder, checked: not a file, not holding an input, and either empty or an
    earlier run's: holding nothing but the ``files`` of one, among them ``mark``, the file every
    run writes (``what`` names that run in the messages)."""
    from raysim.files import check_output_folder

    target = Path(out_dir).expanduser()
    if target.exists() and not target.is_dir():
        raise RenderError(f"{target}: exists and is not a folder")
    check_output_folder(target, inputs, RenderError)
    if target.is_dir():
        held = sorted(p.name for p in target.iterdir())
        other = [name for name in held if name not in files]
        if other:
            raise RenderError(f"{target}: holds files that are not {what} ({other[0]}, ...); "
                              "give a new or empty folder")
        # names alone do not make an earlier run: a crew's own scan.nc or surface.nc in the
        # folder was replaced by the run's, exit 0
        if held and mark not in held:
            raise RenderError(f"{target}: holds {held[0]} but no {mark}, so it is not {what}'s "
                              "folder, and the run would replace it; give a new or empty folder")
    _check_writable(target)
    return target


def _check_writable(target: Path) -> None:
    """Refuse, before any work, an output folder whose parent takes no new folder (the
    staging folder is made there; a read-only mount failed at the end of the run, naming the
    staging folder's internal name)."""
    from raysim.files import probe_writable

    parent = target.resolve().parent
    blocking = next((p for p in (parent, *parent.parents) if p.exists()), None)
    if blocking is not None and not blocking.is_dir():
        raise RenderError(f"{target}: {blocking} is a file, not a folder")
    try:
        parent.mkdir(parents=True, exist_ok=True)
        probe_writable(parent)
    except OSError as exc:
        raise RenderError(f"{target}: cannot write in {parent} ({exc.strerror})") from exc


@contextlib.contextmanager
def staging(target: Path) -> Iterator[Path]:
    """A temporary folder beside ``target`` that replaces it when the block completes.

    What ``target`` held at the start was accepted by the run's checks (nothing, or an earlier
    run's files); anything added or changed in it while the run worked (a crew's notes.txt)
    was deleted with the replaced folder, exit 0. Now ``target`` is left as it is and the result
    kept beside it (:func:`_keep_result`), a RenderError naming both.
    """
    import shutil
    import tempfile

    from raysim.files import changed_since, folder_state, new_folder_mode, remove_stale, writer_prefix

    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale(target)  # what a killed run left (never a live run's staging folder)
    before = folder_state(target)
    tmp = Path(tempfile.mkdtemp(prefix=writer_prefix(target), suffix=".tmp", dir=target.parent))
    old = target.with_name(f".{target.name}.old-{os.getpid()}")
    try:
        yield tmp
        os.chmod(tmp, new_folder_mode())  # mkdtemp's folder is private (0700)
        if added := changed_since(target, before):
            _keep_result(target, tmp, added)
        if target.exists():
            os.replace(target, old)
        os.replace(tmp, target)
        # a file written between the look above and the rename went into the old folder: look
        # again there (nothing writes to it by its name now) and undo the swap if one did
        if added := changed_since(old, before):
            os.replace(target, tmp)
            os.replace(old, target)
            _keep_result(target, tmp, added)
        shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        # an interrupt between the two renames left the old folder hidden: put it back
        if old.exists() and not target.exists():
            os.replace(old, target)
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _keep_result(target: Path, tmp: Path, added: list[str]) -> None:
    """Keep the staged result ``tmp`` as ``TARGET.new`` (``TARGET.new-2``, ... when taken),
    a name no later run removes, and refuse to replace ``target``, which gained ``added``
    while the run worked."""
    import itertools

    for n in itertools.count(1):
        kept = target.with_name(f"{target.name}.new" + (f"-{n}" if n > 1 else ""))
        if not os.path.lexists(kept):
            break
    os.rename(tmp, kept)
    more = f" and {len(added) - 1} more" if len(added) > 1 else ""
    raise RenderError(f"{target}: {added[0]}{more} appeared in it during the run, so it was not "
                      f"replaced; the result is in {kept}")


def inversion() -> Callable[..., xr.Dataset]:
    """The inversion FieldMap -> SurfaceMap of the solver package, as
    ``f(field, solver=None, grid=None, refine=None, device="cpu")``; RenderError when it is not
    installed."""
    try:
        from solver.invert import invert as run
    except ImportError as exc:
        raise RenderError("raysim report needs the solver package (raysim invert), which this "
                          "installation does not have yet") from exc

    def invert(field: xr.Dataset, solver: str | None = None, grid: int | None = None,
               refine: int | None = None, device: str = "cpu") -> xr.Dataset:
        given = {"solver": solver, "N": grid, "refine_iterations": refine}
        return run(field, device=device, **{k: v for k, v in given.items() if v is not None})

    return invert


def write_report(field: xr.Dataset, surface: xr.Dataset | None, out_dir: str | os.PathLike[str], *,
                 timings: dict[str, float] | None = None) -> Path:
    """Draw the figure set for a FieldMap and its SurfaceMap (None: no inversion, the field's
    figures only) and write ``report.html`` with the PNGs beside it in ``figures/``; returns the
    HTML path. ``timings`` (s) are quoted."""
    out = _folder(out_dir)
    (out / "figures").mkdir(exist_ok=True)
    start = time.perf_counter()
    items = _figures(field, surface)
    seconds_draw = time.perf_counter() - start
    blocks = []
    for name, caption, image in items:
        png = png_bytes(image)
        write_bytes(out / "figures" / f"{name}.png", png)
        blocks.append(figure_html(name, caption, png))
    blocks += correction_section(field, surface, out)
    times = {**(timings or {}), "draw": seconds_draw}
    page = _page(field, surface, blocks, times)
    return write_text(out / "report.html", page)


# --- the figures -----------------------------------------------------------------------------
def _figures(field: xr.Dataset, surface: xr.Dataset | None) -> list[tuple[str, str, np.ndarray]]:
    """(file name, caption, RGB image) of every figure, in the paper's order."""
    from raysim.render import charts
    from raysim.render.field3d import field_image
    from raysim.render.surface3d import surface_plotter

    truth = figures.scene_deformation(field)
    truth_map = figures.truth_dataset(field, surface, truth)
    x = figures.aperture_x(field, surface)
    items: list[tuple[str, str, np.ndarray]] = []
    if truth_map is not None:
        items.append(("fig8a_deformation", "Fig. 8a: the assumed deformation delta, height exaggerated as "
                      "stated, colour in µm.", figures.fig8a_deformation(truth_map)))
    items += [
        ("fig8b_ideal_amplitude", "Fig. 8b: amplitude |E| of the ideal reflector on the probe sphere, "
         "plan view and (phi, theta) map.", backend.figure_image(figures.fig8b_ideal_amplitude(field))),
        ("fig8c_fa_sphere", "Fig. 8c: FA = I_ideal / I_def - 1 on the sphere, before resampling.",
         backend.figure_image(figures.fig8c_fa_sphere(field))),
        ("fig8d_fa_aperture", "Fig. 8d: FA after resampling onto the aperture grid through the ideal GO "
         "mapping.", backend.figure_image(figures.fig8d_fa_aperture(field, x))),
        ("fig9_equation", "Fig. 9: FA from the intensities against G times the Laplacian of the true "
         "deformation, along the x and y axes (the deformation-intensity equation).",
         backend.figure_image(figures.fig9_equation(field, x, figures.truth_laplacian(truth, surface)))),
    ]
    if surface is not None:
        wide = (2400, 1000) if "truth" in surface.data_vars else figures.SIZE
        # the page shows every figure at about the same width: the wide ones' text scaled up so
        # that it reads at the size of the others'
        text_scale = wide[0] / figures.SIZE[0]
        items += [
            ("fig10_recovered", "Fig. 10: recovered against true deformation along the x and y axes, "
             "with the error.", backend.figure_image(figures.fig10_recovered(surface))),
            ("surface_maps", "Recovered surface: truth, recovered and error over the aperture (µm).",
             backend.figure_image(charts.surface_map(surface, wide, text_scale))),
        ]
    items.append(("field_3d", "The probe hemisphere coloured by FA over the reflector, focus and plane "
                  "wave marked; inset: the whole antenna.", field_image(field, "fa", figures.SIZE)))
    if surface is not None:
        pl = surface_plotter(surface, wide, text_scale=text_scale)
        items.append(("surface_3d", "Recovered surface as warped dishes (truth, recovered, error), one "
                      "exaggeration.", np.array(backend.screenshot(pl, None))))
        pl.close()
    return items


def correction_section(field: xr.Dataset, surface: xr.Dataset | None, out: Path) -> list[str]:
    """The correction (docs/correction.md) of the recovered map when the scene has panels: the
    corner actuators' commands (piston and tilt left to pointing), before / after maps with the
    panel outlines and the actuators, the obstacle-blocked cells masked, and the command table;
    [] without a map or without panels."""
    from raysim.scene.scene import scene_of

    scene = scene_of(field)
    if surface is None or scene is None or scene.panels is None:
        return []
    from raysim.render.correction import blocked_on_aperture, command_table_html, correction_figure
    from solver.actuators import ActuatorError, corners_layout
    from solver.correction import correct
    from solver.errors import SurfaceMapError
    from solver.surface import grid_of

    layout = scene.panels
    try:
        acts = corners_layout(layout)
    except ActuatorError as exc:
        return [f"<h2>Correction</h2><p>Not drawn: {html.escape(str(exc))}</p>"]
    grid = grid_of(surface)
    try:
        corr = correct(grid, surface["deformation"].values, layout, acts, ("piston", "tilt"))
    except SurfaceMapError as exc:  # a map departing by over 10 cm: the rest of the report stands
        return [f"<h2>Correction</h2><p>Not drawn: {html.escape(str(exc))}</p>"]
    x = surface["x"].values
    blocked = blocked_on_aperture(field, x)
    caption = ("Correction: the recovered map (piston and tilt removed), the surface the corner "
               "actuators' commands leave, and the commands (µm, + toward the focus); panel outlines "
               "and actuators drawn" + ("; cells hidden by obstacles masked grey." if blocked is not None
                                        else "."))
    png = png_bytes(backend.figure_image(correction_figure(x, layout, acts, corr, blocked)))
    (out / "figures" / "correction.png").write_bytes(png)
    return ["<h2>Correction</h2>", figure_html("correction", caption, png),
            command_table_html(acts, corr)]


def png_bytes(image: np.ndarray) -> bytes:
    """An RGB image (height, width, 3) as PNG bytes."""
    from matplotlib.image import imsave

    buffer = io.BytesIO()
    imsave(buffer, image, format="png")
    return buffer.getvalue()


def figure_html(name: str, caption: str, png: bytes) -> str:
    """One embedded figure (base64 PNG) with its caption and a link to the PNG file beside."""
    data = base64.b64encode(png).decode("ascii")
    return (f'<figure id="{name}"><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
            f'<figcaption>{html.escape(caption)} <a href="figures/{name}.png">PNG</a></figcaption>'
            "</figure>")


# --- the page --------------------------------------------------------------------------------
def numbers(field: xr.Dataset, surface: xr.Dataset | None, times: dict[str, float],
            split: tuple[float, float] | None = None) -> list[tuple[str, str]]:
    """The run's figures as (label, value) rows: geometry, data, solver, RMS, RRMS, times
    (``split``: :func:`unseen_harmonic` of ``surface`` where the caller has it already)."""
    a = field.attrs
    s = surface.attrs if surface is not None else {}
    data = f"{method_text(str(a.get('method', '?')))} at {frequency_text(float(a.get('frequency_hz', 0)))}"
    refine = f", {s['refine_iterations']} refinement iterations" if "refine_iterations" in s else ""
    rows = [
        ("scene", str(a.get("scene_name", "measured scan" if a.get("method") == "measured" else "?"))),
        ("dish", f"D = {float(a['diameter']):g} m, F = {float(a['focal_length']):g} m; probe sphere "
                 f"R = {float(a['sphere_radius']):g} m, {field.sizes['theta']} x {field.sizes['phi']} cells"),
        ("data", data + (f", {int(a['rays']):,} rays" if "rays" in a else "")),
    ]
    if surface is None:
        rows.append(("inversion", "not run: the field's figures only"))
    else:
        rows += [
            ("solver", f"{s.get('solver', '?')}, grid {surface.sizes['x']} x {surface.sizes['y']}{refine}"),
            ("boundary", str(s.get("boundary", "?")) + (f"; harmonic part {s['harmonic_part']}"
                                                        if s.get("harmonic_part") else "")),
            ("removed terms", str(s.get("removed_terms", "none") or "none")),
        ]
        rows += _accuracy(field, surface, unseen_harmonic(surface) if split is None else split)
    time_rows = [("simulate", times.get("simulate", a.get("seconds_total"))),
                 ("invert", times.get("invert", s.get("time_s"))), ("draw the figures", times.get("draw"))]
    rows += [(f"time: {label}", f"{float(t):.1f} s") for label, t in time_rows if t is not None]
    return rows


def _accuracy(field: xr.Dataset, surface: xr.Dataset,
              split: tuple[float, float] | None) -> list[tuple[str, str]]:
    """RMS and RRMS rows, recomputed from the maps (RMS over the aperture, RRMS = RMS / M), the
    truth's harmonic part where the data cannot see it (``split``: :func:`unseen_harmonic`),
    and the paper's figure for such data."""
    panels = dict(surface_panels(surface))
    if "error" not in panels:
        return [("recovered", f"RMS {rms(panels['deformation']) * UM:.2f} µm (no truth to compare with)")]
    M = peak_to_peak(panels["truth"])
    err = rms(panels["error"])
    if not M > 0:  # the ideal dish: RRMS = RMS / M means nothing (it raised ZeroDivisionError)
        return [("truth", "flat (the ideal dish, M = 0 µm)"),
                ("recovered - truth", f"RMS {err * UM:.2f} µm, no RRMS")]
    rows = [("truth", f"RMS {rms(panels['truth']) * UM:.2f} µm, peak-to-peak M = {M * UM:.1f} µm"),
            ("recovered - truth", f"RMS {err * UM:.2f} µm, RRMS = RMS / M = {100 * err / M:.2f} %")]
    if split is not None:
        harmonic, rest = split
        rows.append(("harmonic part of the truth",
                     f"RMS {harmonic * UM:.2f} µm (unobservable without rim targets); the error "
                     f"without it: RMS {rest * UM:.2f} µm, RRMS {100 * rest / M:.2f} %"
                     if _sizeable(harmonic, surface) else
                     "negligible (under 1 % of the truth's RMS): the error is the inversion's own"))
    paper = paper_row(field)
    if paper is not None:
        rows.append(("paper", paper))
    return rows


def paper_row(field: xr.Dataset) -> str | None:
    """The paper's own figure for the data of this run, naming its table, or None: for the
    paper's case (its dish, sphere and Eq. 8 deformation at scale 1) the GO case's figures with
    GO data; with PO or PO + PTD data at a frequency of Table 3, that row
    (:data:`raysim.pipeline.paper.TABLE3`); nothing for other data (go+edge, measured, other
    frequencies), which the paper has no figure for."""
    if not _is_paper_case(field):
        return None
    method = str(field.attrs.get("method", ""))
    if method == "go":
        return PAPER_GO
    if method not in PAPER_PO_METHODS:
        return None
    from raysim.pipeline.paper import TABLE3

    f = float(field.attrs.get("frequency_hz", np.nan))
    for hz, (rms_m, rrms_paper) in sorted(TABLE3.items()):
        if abs(f - hz) <= 1e-6 * hz:
            return (f"Table 3, PO & PTD data at {hz / 1e9:g} GHz: FDM (Gauss-Seidel, N = 256, 1000 "
                    f"iterations) RMS {rms_m * UM:.2f} µm, RRMS {100 * rrms_paper:.2f} %")
    return None


def _is_paper_case(field: xr.Dataset) -> bool:
    a = field.attrs
    same = all(abs(float(a.get(k, np.nan)) - v) < 1e-9 for k, v in PAPER_CASE.items())
    return same and str(a.get("deformation", "")) == "paper Eq. 8 x 1"


# --- what the data cannot determine ------------------------------------------------------------
def _harmonic_unobservable(surface: xr.Dataset) -> bool:
    return str(surface.attrs.get("harmonic_part", "")) == HARMONIC_UNOBSERVABLE


def unseen_harmonic(surface: xr.Dataset) -> tuple[float, float] | None:
    """:func:`harmonic_error` where the harmonic part is unobservable (no rim targets), else
    None: the figures both the numbers table and the limits paragraph quote."""
    return harmonic_error(surface) if _harmonic_unobservable(surface) else None


def invert_lines(surface: xr.Dataset) -> list[str]:
    """What ``raysim invert`` prints about the parts of the surface these data leave
    undetermined (the UNOBSERVABLE lines of :func:`solver.run.summary`); [] where the SurfaceMap
    lacks what that summary reads (a hand-made map) or the solver is not installed."""
    try:
        from solver.run import summary

        return [line for line in summary(surface) if "UNOBSERVABLE" in line]
    except (ImportError, KeyError, TypeError, ValueError):
        return []


def harmonic_error(surface: xr.Dataset) -> tuple[float, float] | None:
    """(RMS of the truth's harmonic part, RMS of the error with that part taken out) in m, or
    None without a truth. The truth's harmonic part is the harmonic function with the truth's
    values at the rim (:func:`solver.boundary.fit_harmonic` fitted on the outermost ring of grid
    cells): what the intensities alone cannot see and a map without rim targets leaves out (it
    assumes zero on the rim), so its error holds minus that part; the rest is the inversion's
    own (a harmonic part also leaks a little into the interior: docs/physics.md)."""
    from solver.boundary import RimTargets, fit_harmonic
    from solver.errors import RimTargetsError

    if "error" not in surface.data_vars or "truth" not in surface.data_vars:
        return None
    x, y = surface["x"].values, surface["y"].values
    X, Y = np.meshgrid(x, y)
    R = np.hypot(X, Y)
    truth, error = surface["truth"].values, surface["error"].values
    inside = np.isfinite(error) & np.isfinite(truth)
    if not inside.any():
        return None
    a = 0.5 * float(surface.attrs["diameter"]) if "diameter" in surface.attrs else float(R[inside].max())
    ring = inside & (R > a - 1.5 * abs(float(x[1] - x[0])))
    try:
        h = fit_harmonic(RimTargets(X[ring], Y[ring], truth[ring]), truth[ring], a)
    except RimTargetsError:  # too few cells on the rim to fit
        return None
    part = h(np.arctan2(Y[inside], X[inside]), R[inside])
    return rms(part), rms(error[inside] + part)


def _sizeable(harmonic: float, surface: xr.Dataset) -> bool:
    """Whether a harmonic part of RMS ``harmonic`` (m) is worth a figure: 1 % of the truth's
    RMS at least (below that, the ring of grid cells the fit reads, inside the rim, finds a
    truth that is zero on the rim to be a little harmonic)."""
    truth = surface["truth"].values
    size = rms(truth[np.isfinite(truth)])
    return size > 0 and harmonic >= 0.01 * size  # a flat truth (the ideal dish) has none


def cannot_determine(surface: xr.Dataset, split: tuple[float, float] | None = None) -> list[str]:
    """Sentences on what these data cannot determine: the harmonic part (unless rim targets
    fixed it), with the share of the error it holds and how rim targets fix it, and any other
    unobservable shape (a blocked centre's, delta_c with an estimated gain), in the words of
    ``raysim invert`` (:func:`invert_lines`)."""
    from solver.boundary import MAX_RADIUS_FACTOR, MIN_RADIUS_FACTOR, MIN_TARGETS

    a = surface.attrs
    lines = invert_lines(surface)
    harmonic = [line for line in lines if line.startswith("harmonic part")]
    sentences = []
    if str(a.get("harmonic_part", "")) == HARMONIC_FIXED:
        sentences.append("The harmonic part (tilt, astigmatism, any r^n cos n phi) was fixed here by "
                         f"rim targets ({a.get('boundary', '?')}).")
    elif _harmonic_unobservable(surface):
        sentences.append(_sentence(harmonic[0] if harmonic else "harmonic part unobservable"))
        split = unseen_harmonic(surface) if split is None else split
        panels = dict(surface_panels(surface))
        if split is not None and "truth" in panels and _sizeable(split[0], surface):
            M = peak_to_peak(panels["truth"])
            err = rms(panels["error"])
            sentences.append(f"The truth's harmonic part, which this map cannot hold, has RMS "
                             f"{_um(split[0])} µm; without it the map's error (RMS {_um(err)} µm, "
                             f"RRMS {_pct(err / M)} %) has RMS {_um(split[1])} µm, RRMS "
                             f"{_pct(split[1] / M)} %.")
        sentences.append(f"Rim targets fix it: survey at least {MIN_TARGETS} points between "
                         f"{MIN_RADIUS_FACTOR:g} and {MAX_RADIUS_FACTOR:g} times the rim radius (CSV "
                         "x,y,dz in m) and run raysim invert FIELDMAP.nc -o SURFACE.nc --rim "
                         "targets.csv.")
    sentences += [_sentence(line) for line in lines if line not in harmonic]
    return sentences


def _um(metres: float) -> str:
    return f"{metres * UM:.3g}" if metres * UM >= 0.01 else f"{metres * UM:.2f}"


def _pct(fraction: float) -> str:
    return f"{100 * fraction:.3g}" if 100 * fraction >= 0.01 else f"{100 * fraction:.2f}"


def _sentence(line: str) -> str:
    return line[:1].upper() + line[1:] + ("" if line.endswith(".") else ".")


def scene_overrides(field: xr.Dataset) -> list[str]:
    """What the FieldMap's data differ in from the scene text it records, one phrase each: the
    sphere grid (cells in theta x phi), the frequency (GHz) and the method.

    ``raysim simulate --n-theta 30 --n-phi 60`` (or ``--frequency``, ``--method``) records the
    scene file as written; the report printed that text (n_theta = 90, n_phi = 360) beside
    30 x 60 data. The FieldMap's coordinates and attributes are what ran, so they are compared
    with the text's values (its defaults where it leaves a key out); where the text no longer
    parses here (a file it names is absent), only the keys it writes are compared.
    """
    from raysim.scene.scene import scene_of

    text = field.attrs.get("scene")
    if not text:
        return []
    scene = scene_of(field)
    said: tuple[object, object]  # the text's (n_theta, n_phi), None where unknown
    if scene is not None:
        said = (scene.sphere.n_theta, scene.sphere.n_phi)
        said_frequency: object = scene.source.frequency_hz
        said_method: object = scene.method
    else:
        import tomllib

        try:
            table = tomllib.loads(str(text))
        except tomllib.TOMLDecodeError:
            return []
        sphere, source = table.get("sphere", {}), table.get("source", {})
        said = (sphere.get("n_theta"), sphere.get("n_phi"))
        said_frequency, said_method = source.get("frequency_hz"), table.get("method")
    found = []
    grid = (field.sizes.get("theta"), field.sizes.get("phi"))
    if any(w is not None and w != g for w, g in zip(said, grid, strict=True)):
        shown = " x ".join("?" if w is None else str(w) for w in said)
        found.append(f"sphere grid {grid[0]} x {grid[1]} cells (theta x phi; the text says {shown})")
    frequency = field.attrs.get("frequency_hz")
    if (isinstance(frequency, (int, float)) and isinstance(said_frequency, (int, float))
            and not np.isclose(float(frequency), float(said_frequency), rtol=1e-9, atol=0.0)):
        found.append(f"frequency {float(frequency) / 1e9:.6g} GHz (the text says "
                     f"{float(said_frequency) / 1e9:.6g} GHz)")
    method = field.attrs.get("method")
    if method is not None and said_method is not None and str(method) != str(said_method):
        found.append(f"method {method} (the text says {said_method})")
    return found


def _page(field: xr.Dataset, surface: xr.Dataset | None, blocks: list[str], times: dict[str, float]) -> str:
    split = unseen_harmonic(surface) if surface is not None else None  # one fit for both uses
    rows = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>"
                   for k, v in numbers(field, surface, times, split))
    scene = field.attrs.get("scene")
    overrides = scene_overrides(field)
    overrides_html = (f'<p class="overrides"><strong>This run overrode the scene text:</strong> '
                      f'{html.escape("; ".join(overrides))} (read from the FieldMap).</p>'
                      if overrides else "")
    scene_html = (f"<h2>Scene</h2><pre>{html.escape(str(scene))}</pre>{overrides_html}" if scene else
                  "<h2>Scene</h2><p>None: a measured scan, drawn from the FieldMap's attributes.</p>")
    name = html.escape(str(field.attrs.get("scene_name", "scan")))
    summary = html.escape(error_summary(surface) if surface is not None else "")
    limits = cannot_determine(surface, split) if surface is not None else []
    limits_html = (f'<p class="limits"><strong>What the intensities alone cannot determine:</strong> '
                   f'{html.escape(" ".join(limits))}</p>' if limits else "")
    said = run_warnings(field, surface)
    warnings_html = ('<div class="warnings"><strong>Warnings of this run:</strong><ul>'
                     + "".join(f"<li>{html.escape(w)}</li>" for w in said) + "</ul></div>"
                     if said else "")
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>raysim report: {name}</title>
{PAGE_STYLE}</head><body>
<h1>raysim report: {name}</h1>
<p>Surface deformation from one intensity scan on a hemisphere about the focus. {summary}</p>
{warnings_html}
{limits_html}
<h2>Numbers of this run</h2><table>{rows}</table>
<h2>Figures</h2>
{"".join(blocks)}
{scene_html}
<p>raysim {html.escape(str(field.attrs.get(VERSION_ATTR, "")))}; FieldMap and SurfaceMap beside this
page (field.nc, surface.nc) when the run wrote them.</p>
</body></html>
"""


def run_warnings(field: xr.Dataset | None, surface: xr.Dataset | None) -> list[str]:
    """The warnings the FieldMap and the SurfaceMap carry (their ``*_warning`` attributes: a
    map the model does not reproduce, mostly noise, with a hole, an extrapolated ring, cells
    too coarse; a simulation out of its engine's reach), each as "simulation: ..." or
    "inversion: ...", in the files' order."""
    found = []
    for what, ds in (("simulation", field), ("inversion", surface)):
        if ds is None:
            continue
        found += [f"{what}: {value}" for key, value in ds.attrs.items()
                  if key.endswith("_warning") and str(value).strip()]
    return found


def page_warnings(page: Path, source: str | os.PathLike[str]) -> list[str]:
    """:func:`run_warnings` of a written report ``page``, read back from the maps beside it
    (``field.nc``, or the FieldMap ``source`` it was made from, and ``surface.nc``)."""
    folder = Path(page).parent
    field_path = folder / "field.nc" if (folder / "field.nc").is_file() else Path(source)
    maps = []
    for path in (field_path, folder / "surface.nc"):
        if path.is_file() and path.suffix.lower() in (".nc", ".nc4", ".netcdf"):
            with xr.open_dataset(path) as ds:
                maps.append(xr.Dataset(attrs=dict(ds.attrs)))
        else:
            maps.append(None)
    return run_warnings(*maps)


def _folder(out_dir: str | os.PathLike[str]) -> Path:
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise RenderError(f"{out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    return out


def _save_surface(surface: xr.Dataset, path: Path) -> None:
    """Write the SurfaceMap through its contract's writer (checked, atomic)."""
    from raysim.maps.surfacemap import save

    save(surface, path)
