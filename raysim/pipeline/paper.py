"""The paper's GO case (PAPER.tex Table 2 conditions) run with the project's own GO forward model.

D = 110 m, F = 33 m, R = 10 m, 90 x 360 one-degree cells, the Eq. 8 deformation (peak-to-peak
1.2 mm at scale 1). The paper's figures (GO data): FDM + Gauss-Seidel with 1000 iterations at
N = 256, RRMS 4.06 % in 92 +- 10 s; FFT, RRMS 7.47 %. raysim's rows use the same data and grid.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import xarray as xr

from raysim.errors import RaysimError
from raysim.maps.fieldmap import fieldmap
from raysim.maps.sphere import SphereGrid
from raysim.optics.fast import DEFAULT_TOL
from raysim.scene.scene import check_frequency, check_sphere_cells
from solver.invert import DEFAULT_REFINE, DEFAULT_SOLVER, invert
from solver.options import check_options

D, F, R = 110.0, 33.0, 10.0
FREQUENCY_HZ = 0.3e9


@dataclass
class Row:
    """One line of the comparison: method, the paper's RRMS and time, ours."""

    method: str
    paper_rrms: float | None
    paper_seconds: str
    rrms: float
    rms_m: float
    seconds: float


def paper_fieldmap(scale: float = 1.0, device: str | None = "cpu") -> xr.Dataset:
    """GO FieldMap of the paper's case from the project's engine (Eq. 8 times ``scale``)."""
    from raysim.optics.go import ParaboloidTracer
    from raysim.surface.deformation import PaperDeformation

    grid = SphereGrid(R, 90, 360)
    go = ParaboloidTracer(device)  # one ideal mesh and BVH for both traces
    ideal = go.intensity(grid, F, D)
    deformed = go.intensity(grid, F, D, PaperDeformation(D, F, scale))
    return fieldmap(grid, deformed, ideal, focal_length=F, diameter=D, frequency_hz=FREQUENCY_HZ,
                    method="go", sampling="cell_mean",
                    attrs={"deformation": f"paper Eq. 8 x {scale:g}"})


MAX_SCALE = 50.0  # Eq. 8 x 50: 60 mm peak to peak, far beyond the small-deformation regime


def compare(scale: float = 1.0, N: int = 256, refine: int = DEFAULT_REFINE,
            device: str | None = "cpu", field: xr.Dataset | None = None) -> list[Row]:
    """The paper's GO rows beside ours on the same data; RRMS against Eq. 8 times ``scale``."""
    from raysim.surface.deformation import PaperDeformation

    if not (math.isfinite(scale) and 0 < scale <= MAX_SCALE):
        raise RaysimError(f"--scale must lie in (0, {MAX_SCALE:g}] (1: the paper's 1.2 mm peak to "
                          f"peak), got {scale:g}")
    check_options(N=N, refine=refine)

    field = paper_fieldmap(scale, device) if field is None else field
    truth = PaperDeformation(D, F, scale)
    runs = [
        ("FDM + Gauss-Seidel, 1000 iterations", 0.0406 if scale == 1.0 else None,
         "92 +- 10" if scale == 1.0 else "-",
         {"solver": "gauss-seidel", "iterations": 1000, "refine_iterations": 0}),
        ("FFT (enclosing square)", 0.0747 if scale == 1.0 else None, "-",
         {"solver": "fft", "refine_iterations": 0}),
        (f"raysim linear ({DEFAULT_SOLVER}, refine 0)", None, "-",
         {"solver": DEFAULT_SOLVER, "refine_iterations": 0}),
        (f"raysim default ({DEFAULT_SOLVER}, GO refine {refine})", None, "-",
         {"solver": DEFAULT_SOLVER, "refine_iterations": refine}),
    ]
    rows = []
    for method, paper_rrms, paper_seconds, options in runs:
        start = time.perf_counter()
        result = invert(field, N=N, truth=truth, device=device, **options)
        rows.append(Row(method, paper_rrms, paper_seconds, float(result.attrs["rrms"]),
                        float(result.attrs["rms_m"]), time.perf_counter() - start))
    return rows


def compare_lines(rows: list[Row], scale: float, N: int) -> list[str]:
    """The GO comparison as the lines ``raysim paper`` prints."""
    lines = [f"paper GO case, Eq. 8 x {scale:g}, N = {N}, 90 x 360 cells",
             f"{'method':44s} {'paper RRMS':>10s} {'paper s':>9s} {'RRMS':>9s} {'RMS um':>8s} "
             f"{'time s':>7s}"]
    for row in rows:
        paper = f"{row.paper_rrms * 100:.2f} %" if row.paper_rrms is not None else "-"
        lines.append(f"{row.method:44s} {paper:>10s} {row.paper_seconds:>9s} "
                     f"{row.rrms * 100:7.3f} % {row.rms_m * 1e6:8.2f} {row.seconds:7.2f}")
    return lines


# --- Table 3: PO & PTD data at five frequencies -------------------------------------------
TABLE3_FREQUENCIES_HZ = (0.1e9, 0.3e9, 0.6e9, 1e9, 3e9)
# the paper's Table 3 (FDM + Gauss-Seidel, 1000 iterations, N = 256): RMS (m) and RRMS
TABLE3 = {0.1e9: (264.84e-6, 0.2207), 0.3e9: (85.68e-6, 0.0714), 0.6e9: (61.56e-6, 0.0513),
          1e9: (60.72e-6, 0.0506), 3e9: (77.04e-6, 0.0642)}
PAPER_SETTING = {"solver": "gauss-seidel", "iterations": 1000, "refine_iterations": 0}
# The paper's PO case as a scene: 5 m quadrature faces on the smooth surface (raysim.optics.po),
# the rim as a true circle; the sphere grid is set per frequency.
PO_SCENE = f"""
name = "paper_po_table3"
description = "Paper Table 3: D = 110 m, F = 33 m, R = 10 m, E along x, Eq. 8 deformation"
[dish]
diameter_m = {D}
focal_length_m = {F}
resolution_m = 5.0
[[deformation]]
type = "paper"
scale = 1.0
[source]
frequency_hz = {FREQUENCY_HZ}
polarization_deg = 0.0
[sphere]
radius_m = {R}
n_theta = 90
n_phi = 360
"""


@dataclass
class SweepRow:
    """One frequency of Table 3: the paper's RMS (m) and RRMS beside ours: the paper's setting
    (FDM + Gauss-Seidel, 1000 iterations, linear), the default solver with GO refinement, and
    with the refinement on the data's own wave model (PO + PTD; None above ``wave_max_hz``)."""

    frequency_hz: float
    n_theta: int
    n_phi: int
    paper_rms_m: float | None
    paper_rrms: float | None
    rms_m: float
    rrms: float
    default_rms_m: float
    default_rrms: float
    wave_rms_m: float | None
    wave_rrms: float | None
    seconds_simulate: float
    seconds_invert: float


MAX_SWEEP_HZ = 1e11


#: the sweep's highest frequency of the PO + PTD refinement row when none is asked for (GHz):
#: with the fast radiator each of its forwards takes under a minute up to 1 GHz (the 0.6 and
#: 1 GHz rows together 2.4 min on two cores), with the direct sum 1 GHz alone takes 35 min
WAVE_MAX_GHZ = {"fast": 1.0, "direct": 0.3}


#: the sweep's sphere grid from 2 GHz up when none is asked for: the paper's full 90 x 360 with
#: the fast radiator, whose cost is mostly on the elements' side (at 3 GHz its estimate on
#: 90 x 36 points is 91 % of that on 90 x 360), and 90 x 36 with the direct sum, which costs
#: samples times points (a tenth)
COARSE_GRID = {"fast": (90, 360), "direct": (90, 36)}


def sweep_options(frequencies: str | Sequence[float], coarse: str | tuple[int, int] | None, *,
                  N: int = 256, refine: int = DEFAULT_REFINE, wave_max_ghz: float | None = None,
                  radiator: str = "fast", radiator_tol: float = DEFAULT_TOL) -> dict:
    """The options of :func:`po_sweep` from the command line's text (``"0.1e9,0.3e9"``,
    ``"90x36"``; ``coarse`` None: :data:`COARSE_GRID` for ``radiator``; ``wave_max_ghz`` None:
    :data:`WAVE_MAX_GHZ` for it), checked before anything runs: keyword arguments for
    :func:`po_sweep`."""
    if isinstance(frequencies, str):
        try:
            freqs = [float(f) for f in frequencies.split(",") if f.strip()]
        except ValueError:
            raise RaysimError(f"--frequencies takes frequencies in Hz separated by commas, got "
                              f"{frequencies!r}") from None
    else:
        freqs = [float(f) for f in frequencies]
    if not freqs:
        raise RaysimError("--frequencies names no frequency")
    for f in freqs:
        check_frequency(f, "--frequencies")
        if f > MAX_SWEEP_HZ:
            raise RaysimError(f"--frequencies: {f:g} Hz is above the sweep's {MAX_SWEEP_HZ:g} Hz "
                              "(PO costs grow as f^2)")
    if coarse is None:
        coarse = COARSE_GRID.get(radiator, COARSE_GRID["direct"])
    if isinstance(coarse, str):
        try:
            n_theta, n_phi = (int(n) for n in coarse.lower().split("x"))
        except ValueError:
            raise RaysimError(f"--coarse-3ghz takes a sphere grid such as 90x36, got {coarse!r}") from None
    else:
        n_theta, n_phi = coarse
    check_sphere_cells(n_theta, n_phi, ("--coarse-3ghz n_theta", "--coarse-3ghz n_phi"))
    if wave_max_ghz is None:
        wave_max_ghz = WAVE_MAX_GHZ.get(radiator, WAVE_MAX_GHZ["direct"])
    if not (math.isfinite(wave_max_ghz) and wave_max_ghz >= 0):
        raise RaysimError(f"--wave-max-ghz must be a finite number >= 0, got {wave_max_ghz:g}")
    check_options(N=N, refine=refine, radiator=radiator, radiator_tol=radiator_tol)
    return {"frequencies_hz": tuple(freqs), "coarse": (n_theta, n_phi), "N": N, "refine": refine,
            "wave_max_hz": wave_max_ghz * 1e9}


def sweep_lines(rows: list[SweepRow], N: int, refine: int, wave_max_ghz: float) -> list[str]:
    """Table 3 beside raysim's rows, as the lines ``raysim paper --po`` prints."""
    lines = [f"paper Table 3: PO & PTD (rim) data, Eq. 8 (1.2 mm), R = 10 m, N = {N}",
             f"paper setting: FDM + Gauss-Seidel, 1000 iterations, linear; GO: {DEFAULT_SOLVER} "
             f"with {refine} GO refinements; wave: {DEFAULT_SOLVER} with {refine} PO + PTD "
             f"refinements (the default for PO + PTD data; up to {wave_max_ghz:g} GHz here)",
             f"{'f GHz':>6s} {'sphere grid':>11s} {'paper RMS um':>12s} {'paper RRMS':>10s} "
             f"{'RMS um':>8s} {'RRMS':>8s} {'GO RMS um':>10s} {'GO RRMS':>9s} "
             f"{'wave RMS um':>11s} {'wave RRMS':>9s} {'sim s':>7s}"]
    for r in rows:
        paper_rms = f"{r.paper_rms_m * 1e6:.2f}" if r.paper_rms_m is not None else "-"
        paper_rrms = f"{r.paper_rrms * 100:.2f} %" if r.paper_rrms is not None else "-"
        wave_rms = f"{r.wave_rms_m * 1e6:.2f}" if r.wave_rms_m is not None else "-"
        wave_rrms = f"{r.wave_rrms * 100:.2f} %" if r.wave_rrms is not None else "-"
        lines.append(f"{r.frequency_hz / 1e9:6g} {f'{r.n_theta} x {r.n_phi}':>11s} {paper_rms:>12s} "
                     f"{paper_rrms:>10s} {r.rms_m * 1e6:8.2f} {r.rrms * 100:6.2f} % "
                     f"{r.default_rms_m * 1e6:10.2f} {r.default_rrms * 100:7.2f} % {wave_rms:>11s} "
                     f"{wave_rrms:>9s} {r.seconds_simulate:7.0f}")
    if any(r.n_phi != 360 for r in rows):
        lines.append("coarse grids (fewer phi cells) keep the CPU time in check; the Eq. 8 "
                     "deformation is axially symmetric, so they lose nothing it can show")
    return lines


def po_fieldmap(frequency_hz: float, n_theta: int = 90, n_phi: int = 360, edges: str = "rim",
                device: str | None = "cpu", progress=None, radiator: str = "fast",
                radiator_tol: float = DEFAULT_TOL) -> xr.Dataset:
    """PO + PTD FieldMap of the paper's case at ``frequency_hz`` on an n_theta x n_phi grid
    (``radiator``, ``radiator_tol``: as :func:`raysim.simulate`)."""
    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate

    scene = parse_scene(PO_SCENE, source="paper Table 3").with_overrides(frequency_hz, n_theta, n_phi)
    return simulate(scene, method="po+ptd", edges=edges, device=device, progress=progress,
                    radiator=radiator, radiator_tol=radiator_tol)


def _summed_as(field: xr.Dataset, radiator: str, radiator_tol: float) -> bool:
    """Whether a kept FieldMap's sums are the ones ``radiator`` at ``radiator_tol`` would make
    (the tolerance matters to the fast radiator only)."""
    if field.attrs.get("radiator") != radiator:
        return False
    return radiator != "fast" or field.attrs.get("radiator_tol") == radiator_tol


def _kept_name(f: float, n_theta: int, n_phi: int, radiator: str, radiator_tol: float) -> str:
    """The kept FieldMap's file name: the frequency and grid, and the sums unless they are the
    default's (so that no run replaces a field another run's sums made)."""
    sums = ("" if (radiator, radiator_tol) == ("fast", DEFAULT_TOL)
            else f"_fast_tol{radiator_tol:g}" if radiator == "fast" else f"_{radiator}")
    return f"paper_poptd_{f / 1e9:g}GHz_{n_theta}x{n_phi}{sums}.nc"


def _sums_of(field: xr.Dataset) -> str:
    """How a FieldMap's sums were made, in words, for the line that says it is left as it is."""
    radiator = field.attrs.get("radiator")
    if radiator is None:
        return "radiator not recorded"
    tol = field.attrs.get("radiator_tol")
    return f"radiator {radiator}" + (f", tolerance {tol:g}" if radiator == "fast" and tol is not None else "")


def po_sweep(frequencies_hz=TABLE3_FREQUENCIES_HZ, N: int = 256,
             coarse: tuple[int, int] | None = None, coarse_from_hz: float = 2e9,
             refine: int = DEFAULT_REFINE, device: str | None = "cpu", fields_dir=None,
             log=None, wave_max_hz: float | None = None, radiator: str = "fast",
             radiator_tol: float = DEFAULT_TOL) -> list[SweepRow]:
    """The paper's Table 3 with PO + PTD (rim) data from the project's engines.

    Frequencies at or above ``coarse_from_hz`` use the ``coarse`` (n_theta, n_phi) sphere
    grid (None: :data:`COARSE_GRID` for ``radiator``, the full grid with the fast one): PO's
    samples grow as f^2, and the direct sum's cost with them times the points. The paper's
    deformation is axially symmetric, so fewer phi cells lose little it can show.
    ``fields_dir`` keeps each FieldMap (``paper_poptd_<f>GHz_<grid>.nc``, with the sums in the
    name when they are not the default's: ``_direct``, ``_fast_tol<tol>``) and reuses it on
    the next run that sums as it did; a file of that name summed otherwise (or not saying how)
    is left as it is and the field simulated again. ``log(line)`` reports progress. The
    refinement with the PO + PTD model (:mod:`solver.wave`) runs at frequencies up to
    ``wave_max_hz`` only (None: :data:`WAVE_MAX_GHZ` for ``radiator``): each of its forwards
    is a PO run. ``radiator``: the PO + PTD sums of the data and of that refinement (``fast``
    or ``direct``, as :func:`raysim.simulate`), ``radiator_tol`` the fast sums' relative
    accuracy.
    """
    from pathlib import Path

    from raysim.maps.fieldmap import load, save
    from raysim.surface.deformation import PaperDeformation

    checked = sweep_options(frequencies_hz, coarse, N=N, refine=refine, radiator=radiator,
                            wave_max_ghz=None if wave_max_hz is None else wave_max_hz / 1e9,
                            radiator_tol=radiator_tol)
    coarse, wave_max_hz = checked["coarse"], checked["wave_max_hz"]
    say = log or (lambda line: None)
    truth = PaperDeformation(D, F, 1.0)
    rows = []
    for f in frequencies_hz:
        n_theta, n_phi = coarse if f >= coarse_from_hz else (90, 360)
        path = None
        if fields_dir is not None:
            path = Path(fields_dir) / _kept_name(f, n_theta, n_phi, radiator, radiator_tol)
        start = time.perf_counter()
        field = load(path) if path is not None and path.is_file() else None
        if field is not None and _summed_as(field, radiator, radiator_tol):
            say(f"{f / 1e9:g} GHz: read {path}")
        else:
            if field is not None:
                say(f"{f / 1e9:g} GHz: {path} was summed otherwise ({_sums_of(field)}): left as "
                    "it is")
            keep = field is None
            say(f"{f / 1e9:g} GHz: simulating PO + PTD on {n_theta} x {n_phi} points")
            field = po_fieldmap(f, n_theta, n_phi, device=device, radiator=radiator,
                                radiator_tol=radiator_tol)
            if path is not None and keep:
                path.parent.mkdir(parents=True, exist_ok=True)
                save(field, path)
        simulated = time.perf_counter() - start
        start = time.perf_counter()
        paper = invert(field, N=N, truth=truth, device=device, **PAPER_SETTING)
        default = invert(field, N=N, truth=truth, device=device, refine_iterations=refine,
                         model="go")
        wave_rms = wave_rrms = None
        if f <= wave_max_hz and refine > 0:
            wave = invert(field, N=N, truth=truth, device=device, refine_iterations=refine,
                          radiator=radiator, radiator_tol=radiator_tol)
            wave_rms, wave_rrms = float(wave.attrs["rms_m"]), float(wave.attrs["rrms"])
        paper_rms, paper_rrms = TABLE3.get(f, (None, None))
        rows.append(SweepRow(f, n_theta, n_phi, paper_rms, paper_rrms, float(paper.attrs["rms_m"]),
                             float(paper.attrs["rrms"]), float(default.attrs["rms_m"]),
                             float(default.attrs["rrms"]), wave_rms, wave_rrms, simulated,
                             time.perf_counter() - start))
        wave_text = f", {100 * wave_rrms:.2f} % (PO + PTD refinement)" if wave_rrms else ""
        say(f"{f / 1e9:g} GHz: RRMS {100 * rows[-1].rrms:.2f} % (paper setting), "
            f"{100 * rows[-1].default_rrms:.2f} % (GO refinement){wave_text}")
    return rows
