"""What a SurfaceMap records of its inversion: every choice, the data's coverage, the accuracy.

Units: lengths in m, angles in the attributes' own unit (``*_deg`` in degrees), times in s.
The attributes are flat numbers and strings (NetCDF cannot hold nested ones); their meaning
is the SurfaceMap contract's (:mod:`raysim.maps.surfacemap`, ``docs/data.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from raysim.maps.probe import probe_of
from solver import metrics
from solver.aperture import ApertureGrid
from solver.fit import remove_terms
from solver.linear import LinearInverse, LinearSolution, Scan
from solver.nonlinear import RefineHistory
from solver.refinement import RefinementSetup

if TYPE_CHECKING:
    from solver.invert import InvertOptions, MeasuredFA


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


def surface_attrs(opts: InvertOptions, out: Outcome) -> dict[str, Any]:
    """The SurfaceMap attributes of an inversion with settings ``opts`` and results ``out``."""
    scan, linear, setup, history = out.scan, out.linear, out.setup, out.history
    gain = opts.gain
    gain_factor = out.gain_factor if out.gain_factor is not None else (
        history.gain_factor[-1] if history.gain_factor else 1.0)
    attrs: dict[str, Any] = {
        "solver": opts.solver, "solver_iterations": linear.info.iterations,
        "solver_residual": linear.info.residual, "solver_converged": linear.info.converged,
        "boundary": out.inverse.describe_boundary(),
        "harmonic_part": "fixed by rim targets" if opts.rim is not None else "unobservable",
        "harmonic_observable": opts.rim is not None,
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
        "refine_seconds": history.seconds,
        "gain_mode": gain, "gain": out.data.scale * gain_factor,
        "gain_source": _gain_source(gain, setup.fit_gain and bool(history.gain_factor)),
        "noise_relative_std": float(np.sqrt(out.data.noise_variance)),
        "noise_source": out.data.noise_source,
        "noise_bias": "removed: FA -> (1 + FA) / (1 + v) - 1" if gain == "power" else
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


def _gain_source(gain: str, fitted: bool) -> str:
    if fitted:
        return "GO power balance, then fitted with the surface by the wave refinement"
    if gain == "power":
        return "GO power balance (deformed and ideal send equal power)"
    return "none (trusted)"


def accuracy_attrs(grid: ApertureGrid, delta: NDArray[np.float64], delta_out: NDArray[np.float64],
                   truth: NDArray[np.float64], terms: Sequence[str]
                   ) -> tuple[dict[str, float], NDArray[np.float64]]:
    """RMS and RRMS of the recovered map against the truth (m), the paper's definitions.

    ``delta`` is the map before the term removal, ``delta_out`` after; the truth gets the same
    removal, and is returned so (the SurfaceMap's ``truth``). RRMS = RMS / peak-to-peak of the
    truth before removal.
    """
    M = metrics.peak_to_peak(grid, truth)
    before = metrics.rms_error(grid, delta, truth)
    removed, _ = remove_terms(grid, truth, terms)
    rms = metrics.rms_error(grid, delta_out, removed)
    return ({"rms_before_removal_m": before, "rms_m": rms, "rrms": rms / M,
             "truth_peak_to_peak_m": M}, removed)
