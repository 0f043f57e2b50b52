"""What a SurfaceMap records of its inversion: every choice, the data's coverage, the accuracy.

Units: lengths in m, angles in the attributes' own unit (``*_deg`` in degrees), times in s.
The attributes are flat numbers and strings (NetCDF cannot hold nested ones); their meaning
is the SurfaceMap contract's (:mod:`raysim.maps.surfacemap`, ``docs/data.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from raysim.maps.probe import probe_of
from raysim.maps.sphere import SphereGrid
from raysim.maps.surfacemap import HARMONIC_FIXED, HARMONIC_UNOBSERVABLE
from solver import metrics
from solver.aperture import ApertureGrid
from solver.boundary import harmonic_order
from solver.fit import remove_terms
from solver.gainmode import MeasuredFA
from solver.linear import LinearInverse, LinearSolution, Scan
from solver.nonlinear import RefineHistory
from solver.options import InvertOptions
from solver.refinement import RefinementSetup
from solver.resample import (
    HOLE_SHARE_WARNING,
    RING_SHARE_WARNING,
    SAMPLING_RADIAL_SHARE,
    SAMPLING_RIM_SHARE,
    Hole,
    cell_spacing,
    unmeasured_ring,
)
from solver.unobservable import Unobservable


@dataclass(frozen=True)
class Outcome:
    """The results of an inversion's steps that its SurfaceMap describes."""

    scan: Scan
    grid: ApertureGrid
    inverse: LinearInverse
    linear: LinearSolution
    data: MeasuredFA
    setup: RefinementSetup
    history: RefineHistory
    weighted: bool
    removed: dict[str, float]
    gain_factor: float | None = None  # the final scale factor when Gauss-Newton refitted it
    delta_c: float = 0.0  # the removed multiple of the delta_c mode (an FA offset)
    delta_c_mode: NDArray[np.float64] | None = None  # the mode (m per unit FA), None: kept


def surface_attrs(opts: InvertOptions, out: Outcome) -> dict[str, Any]:
    """The SurfaceMap attributes of an inversion with settings ``opts`` and results ``out``."""
    scan, linear, setup, history = out.scan, out.linear, out.setup, out.history
    gain = out.data.gain
    gain_factor = out.gain_factor if out.gain_factor is not None else (
        history.gain_factor[-1] if history.gain_factor else 1.0)
    attrs: dict[str, Any] = {
        "solver": opts.solver, "solver_iterations": linear.info.iterations,
        "solver_residual": linear.info.residual, "solver_converged": linear.info.converged,
        "boundary": out.inverse.describe_boundary(),
        "harmonic_part": HARMONIC_FIXED if opts.rim is not None else HARMONIC_UNOBSERVABLE,
        "harmonic_observable": opts.rim is not None,
        # the order the targets' spread fixes: the rim's harmonics above it are assumed zero
        # (16 targets over half the rim fix order 1: the map 99 um off, and it said "fixed")
        **({"rim_harmonic_order": harmonic_order(opts.rim)} if opts.rim is not None else {}),
        "removed_terms": ",".join(opts.terms) or "none",
        "refine_iterations": opts.refine_iterations,
        "refine_model": setup.model,
        "refine_model_choice": setup.choice,
        "refine_method": "defect correction with Anderson acceleration; forward model: "
                         + setup.description,
        "refine_preconditioner": setup.preconditioner,
        "refine_gain_factor": ",".join(f"{v:.9f}" for v in history.gain_factor) or "none",
        "weights": "amplitude: FA times sqrt(I_ideal / I_GO) per sphere cell (1 for GO data)"
                   if out.weighted else "none",
        "refine_update_rms_m": ",".join(f"{v:.3e}" for v in history.update_rms),
        "refine_misfit_rms": ",".join(f"{v:.3e}" for v in history.misfit_rms),
        "refine_stopped": history.stopped or "no: every iteration ran",
        # how many times each kept update was halved before it lowered the misfit (0: full step)
        "refine_backtracks": ",".join(str(v) for v in history.backtracks),
        "refine_forward_runs": history.evaluations,
        **_fit_attrs(out),
        "refine_seconds": history.seconds,
        "gain_mode": gain.mode, "gain_known": not gain.estimated, "gain_choice": gain.reason,
        "gain": out.data.scale * gain_factor,
        "gain_std": out.data.estimate.std, "gain_coverage": out.data.estimate.coverage,
        "gain_source": _gain_source(gain.estimated, setup.fit_gain and bool(history.gain_factor)),
        **_delta_c_attrs(out),
        "noise_relative_std": float(np.sqrt(out.data.noise_variance)),
        "noise_source": out.data.noise_source,
        "noise_bias": "removed: FA -> (1 + FA) / (1 + v) - 1" if gain.estimated else
                      "removed: FA -> (1 + FA) / (1 + v/2) - 1 (noise symmetric in dB)",
        "samples_missing": out.data.missing,
        "missing_samples": "filled by least-squares Laplacian inpainting on the (theta, phi) "
                           "grid",
        "theta_last_used_deg": float(np.degrees(linear.coverage.theta_last)),
        "theta_rim_deg": float(np.degrees(linear.coverage.theta_rim)),
        "rms_definition": f"over the {out.grid.n_inside} grid points inside r < D/2",
        "focal_length": scan.F, "diameter": scan.D, "sphere_radius": scan.R,
        "data_method": str(scan.attrs.get("method", "")),
        "data_frequency_hz": float(scan.attrs.get("frequency_hz", 0.0)),
    }
    for name, value in out.removed.items():
        attrs[f"removed_{name}"] = value
    probe = probe_of(scan.attrs)
    if not probe.ideal:  # the probe the scan was read with (raysim.maps.probe)
        attrs["data_probe"] = probe.describe()
    return attrs


def hole_attrs(hole: Hole | None) -> dict[str, Any]:
    """The scan's largest hole of missing readings (:meth:`solver.linear.Scan.check_coverage`),
    with a warning above :data:`solver.resample.HOLE_SHARE_WARNING` of the cells."""
    if hole is None:
        return {"largest_hole_share": 0.0}
    attrs: dict[str, Any] = {"largest_hole_share": hole.share, "largest_hole": hole.describe()}
    if hole.share > HOLE_SHARE_WARNING:
        attrs["hole_warning"] = (f"the scan misses a region ({hole.describe()}), filled by "
                                 "a smooth guess: the map there is not measured")
    return attrs


def ring_attrs(scan: Scan) -> dict[str, Any]:
    """The ring between the scan's last usable row and the rim, which the spline extrapolates
    (:func:`solver.resample.unmeasured_ring`), with a warning above
    :data:`solver.resample.RING_SHARE_WARNING` of the radius."""
    share, reached = unmeasured_ring(scan.sphere, scan.F, scan.D)
    attrs: dict[str, Any] = {"unmeasured_ring_share": share}
    if share > RING_SHARE_WARNING:
        attrs["ring_warning"] = (f"the scan's last row inside the rim image reaches the dish at "
                                 f"r = {reached:.3g} m of {0.5 * scan.D:.3g} m: the ring beyond "
                                 f"({100 * share:.0f} % of the radius) is extrapolated, not "
                                 "measured; scan in finer rows to the rim image")
    return attrs


def sampling_attrs(scan: Scan) -> dict[str, Any]:
    """How far apart the scan's cells meet the dish (:func:`solver.resample.cell_spacing`),
    with a warning above :data:`solver.resample.SAMPLING_RADIAL_SHARE` of the diameter between
    rows or :data:`solver.resample.SAMPLING_RIM_SHARE` between columns at the rim."""
    radial, arc = cell_spacing(scan.sphere, scan.F, scan.D)
    attrs: dict[str, Any] = {"cell_spacing_radial_m": radial, "cell_spacing_rim_m": arc}
    radial_max, arc_max = SAMPLING_RADIAL_SHARE * scan.D, SAMPLING_RIM_SHARE * scan.D
    if radial > radial_max or arc > arc_max:
        attrs["sampling_warning"] = (
            f"the scan's cells meet the dish up to {radial:.3g} m apart radially and {arc:.3g} m "
            f"apart round the rim, on a {scan.D:.3g} m dish: the map holds nothing finer than "
            "about twice that, and finer detail of the surface aliases into it; scan finer "
            f"cells (under {radial_max:.2g} m radially and {arc_max:.2g} m round the rim) for a "
            "map to act on")
    return attrs


#: the share of the scan's usable readings equal to its largest above which the meter is said
#: to have saturated, where that is also SATURATED_PILE times as many as any of the next
#: three values below it hold: a meter over its range reads one constant, so the clipped
#: readings pile up there; a display's rounding (0.01 dB) repeats values too, but its top
#: value holds no more than those just below (the paper's scan rounded so: 2.6 % at the top)
SATURATED_SHARE_WARNING = 0.02
SATURATED_MIN_CELLS = 10
SATURATED_PILE = 5.0


def saturation_attrs(scan: Scan, n_rows: int) -> dict[str, Any]:
    """A warning where many of the scan's readings in its first ``n_rows`` (usable) rows are
    exactly its largest: a saturated meter's plateau, whose cells' FA is wrong (readings
    clipped at the 95th percentile gave a 2.5 mm RMS map of a 0.2 mm surface, with the gain
    trusted, and not a word)."""
    readings = scan.intensity[:n_rows]
    readings = readings[np.isfinite(readings)]
    if readings.size == 0:
        return {}
    values, counts = np.unique(readings, return_counts=True)
    top, count = float(values[-1]), int(counts[-1])
    below = int(counts[-4:-1].max(initial=0))
    if (count < max(SATURATED_MIN_CELLS, SATURATED_SHARE_WARNING * readings.size)
            or count < SATURATED_PILE * below):
        return {}
    return {"saturation_warning": (
        f"{count} readings ({100 * count / readings.size:.0f} % of the scan inside the rim image) "
        f"equal its largest, {top:.6g}: a meter over its range reads one constant, so those "
        "cells' FA is wrong and the map with it; measure again with more attenuation before "
        "the meter")}


def rim_attrs(shift: NDArray[np.float64], dropped: int, sphere: SphereGrid) -> dict[str, Any]:
    """How far the map moves the rim's image (:mod:`solver.rimimage`), and the rows that left
    out of the solve (``sphere`` is the grid of the rows kept)."""
    attrs: dict[str, Any] = {"rim_image_shift_deg": float(np.degrees(np.max(np.abs(shift)))),
                             "rows_dropped_at_rim": int(dropped)}
    if dropped:
        lo = float(np.degrees(sphere.theta_max))
        hi = lo + dropped * float(np.degrees(sphere.dtheta))
        rows, lit = (("the row", "it is") if dropped == 1 else
                     (f"the {dropped} rows", "they are"))
        attrs["rows_dropped_why"] = (
            f"the map moves the rim's image by up to {attrs['rim_image_shift_deg']:.3f} deg, "
            f"past the outer edge of {rows} {lo:.2f}..{hi:.2f} deg, so {lit} lit only in part: "
            "left out, and the map solved again without them")
    return attrs


#: the refinement's last misfit over the data's FA RMS above which (and above three times the
#: noise) the map is said not to reproduce the scan: clean GO data of surfaces GO inverts leave
#: under 0.07, surfaces past its linear range (20 mm bumps of 2 m on a 50 m dish) 0.16 to 25
MISFIT_SHARE_WARNING = 0.1


def _fit_attrs(out: Outcome) -> dict[str, Any]:
    """How much of the scan the refinement's model leaves unexplained (none without a model)."""
    misfits = out.history.misfit_rms
    return fit_attrs(out.data, misfits[-1]) if misfits else {}


def fit_attrs(data: MeasuredFA, last: float) -> dict[str, Any]:
    """The SurfaceMap attributes of the model's last misfit ``last`` (RMS of FA over the
    compared cells) against the data's FA (see :data:`MISFIT_SHARE_WARNING`); Gauss-Newton's
    replace the defect correction's when it ran after it."""
    fa = data.fa[:data.n_rows]
    data_rms = float(np.sqrt(np.nanmean(fa**2))) if np.any(np.isfinite(fa)) else 0.0
    noise = float(np.sqrt(data.noise_variance))
    if not np.isfinite(last):  # the model of the map leaves most cells dark (solver.nonlinear)
        return {"refine_data_fa_rms": data_rms, "refine_warning": (
            "the model of the map leaves more than half of the scan's cells dark (its rays cross "
            "or leave the sphere): the surface is beyond the model's reach, far outside the "
            "equation's linear range, and the map is only the linear answer; do not act on it")}
    share = last / data_rms if data_rms > 0 else float("nan")
    attrs: dict[str, Any] = {"refine_data_fa_rms": data_rms, "refine_misfit_share": share}
    if data_rms > 0 and share > MISFIT_SHARE_WARNING and last > 3.0 * noise:
        part = (f"{share * 100:.0f} % of" if share < 10 else
                f"{share:.3g} times")  # a caustic's intensities: 6e16 against 2.5
        attrs["refine_warning"] = (
            f"the model leaves {part} the data's FA unexplained (misfit "
            f"{last:.2e} RMS against {data_rms:.2e}, noise {noise:.1e}): the map does not "
            "reproduce the scan (a surface beyond GO's linear range, or data the model does "
            "not describe); do not act on it without checking")
    return attrs


#: the share of the map's own RMS above which the readings' noise alone is said to make the map
#: (0.05 dB per reading on a sphere at 0.9 F spread a 50 m dish's map by 1 130 um, against a
#: 200 um peak-to-peak surface: 572 um of error, and nothing said so without a stated std)
NOISE_SHARE_WARNING = 0.5
#: no warning for a spread under 0.01 um (m): the clean map of a flat truth is 1e-12 m, all of it
#: rounding, and nothing to act on
NOISE_WARNING_FLOOR = 1e-8


def um_text(value: float) -> str:
    """A length (m) in um for a summary: two decimals from 0.01 to 100 um, whole um above,
    two digits below (0.0034, not 0.00)."""
    um = value * 1e6
    if abs(um) >= 100:
        return f"{um:.0f}"
    return f"{um:.2f}" if abs(um) >= 0.01 or um == 0 else f"{um:.2g}"


def noise_spread_attrs(spread: float, stated: bool, data: MeasuredFA, size: float,
                       of_map: str = "the map's own RMS") -> dict[str, Any]:
    """The SurfaceMap attributes of the map's spread under the readings' noise: ``spread`` (m
    RMS over the disk; NaN when not measured), the Monte Carlo of the linear inversion under
    the stated ``intensity_std`` (``stated``) or under the noise estimated from the scan; with
    a warning when it is a large share of ``size``, the RMS (m) of the map ``of_map`` names."""
    if not np.isfinite(spread):
        return {}
    attrs: dict[str, Any] = {
        "noise_map_rms_m": float(spread),
        "noise_map_rms_from": "Monte Carlo of the linear inversion under the " + (
            "scan's stated intensity_std" if stated else
            f"readings' noise {data.noise_source}, the same in every cell"),
    }
    if spread > NOISE_SHARE_WARNING * max(size, NOISE_WARNING_FLOOR):
        db = 10.0 / np.log(10.0) * float(np.sqrt(data.noise_variance))  # as the budget's dB
        share = f"{100 * spread / size:.0f} % of" if size > 0 else "more than"
        attrs["noise_warning"] = (
            f"the readings' noise ({db:.2g} dB per cell) alone spreads the map by "
            f"{um_text(spread)} um RMS, {share} {of_map} "
            f"({um_text(size)} um): the map is mostly noise; average more readings per point "
            "(raysim budget gives how many a target RMS needs)")
    return attrs


def map_rms(delta: NDArray[np.float64]) -> float:
    """RMS (m) of a map over its finite cells; 0 where it has none."""
    inside = delta[np.isfinite(delta)]
    return float(np.sqrt(np.mean(inside**2))) if inside.size else 0.0


def _delta_c_attrs(out: Outcome) -> dict[str, Any]:
    """How the map treats delta_c, the shape a scale error makes (:mod:`solver.gainmode`)."""
    if out.delta_c_mode is None:
        return {"delta_c_part": "kept: the gain is known, so delta_c is fixed by the data",
                "delta_c_observable": True}
    centre = out.delta_c_mode[out.grid.N // 2, out.grid.N // 2]
    return {"delta_c_part": "removed: unobservable with an estimated gain (G Laplacian(delta_c) "
                            "= const, zero on the rim)",
            "delta_c_observable": False, "removed_delta_c": out.delta_c,
            "removed_delta_c_centre_m": float(out.delta_c * centre) if np.isfinite(centre)
            else float("nan")}


def _gain_source(estimated: bool, fitted: bool) -> str:
    if fitted:
        return "GO power balance, then fitted with the surface by the wave refinement"
    if estimated:
        return "GO power balance (deformed and ideal send equal power)"
    return "none (trusted)"


def accuracy_attrs(grid: ApertureGrid, delta: NDArray[np.float64], delta_out: NDArray[np.float64],
                   truth: NDArray[np.float64], terms: Sequence[str],
                   unseen: Unobservable | None = None
                   ) -> tuple[dict[str, float], NDArray[np.float64]]:
    """RMS and RRMS of the recovered map against the truth (m), the paper's definitions.

    ``delta`` is the map with the ``unseen`` modes removed (:mod:`solver.unobservable`), before
    the terms' removal; ``delta_out`` after it. The truth gets the same removals, the modes'
    projection then the terms, and is returned so (the SurfaceMap's ``truth``). RRMS = RMS /
    peak-to-peak of the truth as it is (NaN for a flat truth, the ideal dish).
    """
    M = metrics.peak_to_peak(grid, truth)
    removed = truth if unseen is None else unseen.remove(grid, truth)[0]
    before = metrics.rms_error(grid, delta, removed)
    removed, _ = remove_terms(grid, removed, terms)
    rms = metrics.rms_error(grid, delta_out, removed)
    return ({"rms_before_removal_m": before, "rms_m": rms, "rrms": rms / M if M > 0 else float("nan"),
             "truth_peak_to_peak_m": M}, removed)
