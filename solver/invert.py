"""The inversion pipeline: FieldMap (intensity on the sphere) -> SurfaceMap (delta on the aperture).

Frame and units (DESIGN.md): sphere angles in rad, aperture x, y and delta in m.

Steps: gain (power ratio or none) -> FA on the sphere -> resample to the aperture grid ->
Laplacian(delta) = FA / G on the disk with rim values (zero, or fitted to rim targets) ->
model-based refinement (``refine`` iterations of a forward model: GO, or PO / PO+PTD for wave
data, chosen from the FieldMap's ``method`` unless the caller names one) -> optional removal of
piston, tilt and focus -> RMS / RRMS against the truth when it is known -> SurfaceMap with
every choice recorded.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from raysim.maps.fieldmap import grid_of
from raysim.maps.fieldmap import validate as validate_fieldmap
from raysim.maps.sphere import SphereGrid
from solver import boundary, metrics
from solver.aperture import ApertureGrid
from solver.equation import (
    GAIN_MODES,
    G,
    debias,
    intensity_ratio_fa,
    noise_variance,
    power_gain,
    stated_noise_variance,
)
from solver.errors import SolverError
from solver.fit import parse_terms, remove_terms
from solver.forward import MODELS, Progress
from solver.gauss_newton import REFINE_METHODS, choose_method, refine_gauss_newton, report_attrs
from solver.nonlinear import Forward, extend_outside, refine
from solver.poisson import SOLVERS, SolveInfo, solve_poisson
from solver.refinement import choose_model, refinement_setup
from solver.resample import Coverage, fill_missing, sphere_to_aperture, usable_rows
from solver.surface import surfacemap
from solver.wave import amplitude_weight

DEFAULT_SOLVER = "multigrid"
DEFAULT_N = 256
DEFAULT_REFINE = 3
WEIGHTS = ("auto", "amplitude", "none")
MAX_INCIDENCE = 1e-3  # rad: the equation and the GO model assume an on-axis plane wave


@dataclass
class Scan:
    """What the inversion reads from a FieldMap (attributes alone, no scene needed)."""

    sphere: SphereGrid
    F: float
    D: float
    R: float
    intensity: NDArray[np.float64]
    intensity_ideal: NDArray[np.float64]
    intensity_std: NDArray[np.float64] | None
    attrs: dict

    @classmethod
    def from_fieldmap(cls, ds: xr.Dataset) -> Scan:
        ds = validate_fieldmap(ds)
        tilt = float(ds.attrs.get("incidence_theta", 0.0))
        if abs(tilt) > MAX_INCIDENCE:
            raise SolverError(f"the inversion assumes an on-axis plane wave; this scan's source "
                              f"is {np.degrees(tilt):.3f} deg off axis")
        std = ds["intensity_std"].values if "intensity_std" in ds.data_vars else None
        return cls(grid_of(ds), float(ds.attrs["focal_length"]), float(ds.attrs["diameter"]),
                   float(ds.attrs["sphere_radius"]), ds["intensity"].values.astype(np.float64),
                   ds["intensity_ideal"].values.astype(np.float64),
                   None if std is None else std.astype(np.float64), dict(ds.attrs))


class LinearInverse:
    """The linear map FA on the sphere -> delta on the aperture, with one rim treatment.

    State: the scan geometry, the aperture grid and solver settings, the rim targets and the
    rim series fitted so far.
    """

    def __init__(self, scan: Scan, grid: ApertureGrid, solver: str, *, iterations=None,
                 omega=None, tol=1e-10, targets: boundary.RimTargets | None = None,
                 max_harmonics: int = boundary.MAX_HARMONICS) -> None:
        self.scan, self.grid, self.solver = scan, grid, solver
        self.options = {"iterations": iterations, "omega": omega, "tol": tol}
        self.targets, self.max_harmonics = targets, max_harmonics
        self.G = G(grid.r, scan.F, scan.R)
        self.rim = boundary.zero_rim(grid.a)
        self.info = SolveInfo(solver)
        self.coverage: Coverage | None = None
        self.weight: NDArray[np.float64] | None = None  # on the sphere, applied by solve()

    def poisson(self, fa_aperture, g=None) -> NDArray[np.float64]:
        rhs = np.where(self.grid.mask, fa_aperture / self.G, 0.0)
        delta, self.info = solve_poisson(self.grid, rhs, g, self.solver, **self.options)
        return delta

    def to_aperture(self, fa_sphere) -> NDArray[np.float64]:
        fa, self.coverage = sphere_to_aperture(fa_sphere, self.scan.sphere, self.grid,
                                               self.scan.F, self.scan.D)
        return fa

    def rim_update(self, delta) -> NDArray[np.float64]:
        """Harmonic correction (m) that moves ``delta`` onto the rim targets (zero without)."""
        if self.targets is None:
            return np.zeros_like(delta)
        from scipy.interpolate import RegularGridInterpolator  # slow to import; rims only

        filled = extend_outside(self.grid, delta)
        at = RegularGridInterpolator((self.grid.y, self.grid.x), filled, bounds_error=False,
                                     fill_value=None)
        misfit = self.targets.dz - at(np.stack([self.targets.y, self.targets.x], axis=-1))
        series = boundary.fit_harmonic(self.targets, misfit, self.grid.a, self.max_harmonics)
        self.rim = self.rim + series
        return self.poisson(np.zeros_like(delta), series)

    def solve(self, fa_sphere) -> NDArray[np.float64]:
        """delta (m) for FA on the sphere (times ``weight``), rim values zero or fitted."""
        if self.weight is not None:
            fa_sphere = fa_sphere * self.weight
        delta = self.poisson(self.to_aperture(fa_sphere))
        return delta + self.rim_update(delta)

    def correct(self, misfit_sphere, delta) -> NDArray[np.float64]:
        """Update (m) of ``delta`` for an FA misfit, keeping the rim on the targets."""
        update = self.poisson(self.to_aperture(misfit_sphere))
        return update + self.rim_update(delta + update)

    def describe_boundary(self) -> str:
        if self.solver == "fft":
            return "zero on the enclosing square (fft); the rim of the disk is free"
        if self.targets is None:
            return "zero on the rim (the paper's assumption)"
        return (f"rim targets: {len(self.targets)} points from {self.targets.source}, "
                f"harmonic fit of order {self.rim.order}")


def _truth_from_scene(attrs: dict) -> Callable | None:
    text = attrs.get("scene")
    if not text:
        return None
    try:
        from raysim.scene.scene import parse_scene

        return parse_scene(str(text), source="FieldMap scene").deformation
    except Exception:  # a scene that no longer parses just means no truth
        return None


def invert(field: xr.Dataset, *, solver: str = DEFAULT_SOLVER, N: int = DEFAULT_N,
           rim: boundary.RimTargets | None = None, remove: str | Sequence[str] | None = None,
           refine_iterations: int = DEFAULT_REFINE, gain: str = "power",
           iterations: int | None = None, omega: float | None = None, tol: float = 1e-10,
           truth: Callable | NDArray | str | None = "scene", forward: Forward | None = None,
           device: str | None = "cpu", uncertainty_samples: int = 32, seed: int = 0,
           max_harmonics: int = boundary.MAX_HARMONICS, model: str | None = None,
           weights: str = "auto", progress: Progress | None = None,
           refine_method: str = "defect", gauss_newton=None, log=None) -> xr.Dataset:
    """Recover the surface deformation from a FieldMap; return a SurfaceMap.

    Parameters
    ----------
    field : a FieldMap dataset (intensity, intensity_ideal; attrs focal_length, diameter,
        sphere_radius in m).
    solver : Poisson solver, one of :data:`solver.poisson.SOLVERS`.
    N : aperture grid points across the diameter (>= 16).
    rim : rim targets (x, y, dz in m) fixing the harmonic part; None assumes zero on the rim.
    remove : terms to remove after the solve: any of piston, tilt, focus.
    refine_iterations : model refinement iterations; 0 gives the linear answer.
    gain : ``power`` estimates the scan's scale from its total power; ``none`` trusts it.
    iterations, omega, tol : settings of the iterative solvers (see :func:`solve_poisson`).
    truth : None, a callable delta(x, y) (m), an (N, N) array (m), or ``"scene"`` (the
        FieldMap's scene deformation when it carries a scene).
    forward : the refinement's forward model (a callable, see :mod:`solver.forward`); None
        builds the one ``model`` names.
    device : Warp device of the forward model (``cpu`` or ``cuda``).
    uncertainty_samples : Monte Carlo draws for ``deformation_std`` (when intensity_std exists).
    seed : random seed of the Monte Carlo draws.
    max_harmonics : highest Fourier order of the rim fit.
    model : the refinement's forward model, one of :data:`solver.forward.MODELS` (``go``,
        ``po``, ``po+ptd``); None picks the one that made the data (FieldMap ``method``: GO for
        GO data, PO for PO data, GO for a measured scan). A wave model brings its own
        preconditioner (:class:`solver.wave.WaveCorrection`) and, unless ``gain="none"``,
        fits the scan's scale with the surface.
    weights : ``amplitude`` multiplies FA (and every refinement misfit) by sqrt(I_ideal /
        I_GO) per sphere cell, which keeps wave data's response near GO's in the dark rings
        of the diffraction pattern (:func:`solver.wave.amplitude_weight`; 1 for GO data);
        ``none`` uses FA as the paper does; ``auto`` (default) weights when the refinement
        runs a wave model, so the linear answer (refine 0) stays the paper's equation.
    progress : optional ``progress(stage, fraction)`` of the refinement (0..1).
    refine_method : ``defect`` (defect correction only, the default), ``gauss-newton`` (then
        Gauss-Newton with the wave model's exact Jacobian, :mod:`solver.gauss_newton`) or
        ``auto`` (Gauss-Newton for a wave model where it is affordable: see
        :func:`solver.gauss_newton.choose_method`).
    gauss_newton : :class:`solver.gauss_newton.GaussNewtonOptions` (None: defaults).
    log : optional ``log(line)`` of the Gauss-Newton steps (misfit, update, time).
    """
    start = time.perf_counter()
    if solver not in SOLVERS:
        raise SolverError(f"unknown solver {solver!r}: choose one of {', '.join(SOLVERS)}")
    if gain not in GAIN_MODES:
        raise SolverError(f"unknown gain mode {gain!r}: choose one of {', '.join(GAIN_MODES)}")
    if refine_iterations < 0:
        raise SolverError(f"refine must be >= 0, got {refine_iterations}")
    if model is not None and model not in MODELS:
        raise SolverError(f"unknown model {model!r}: choose one of {', '.join(MODELS)}")
    if weights not in WEIGHTS:
        raise SolverError(f"unknown weights {weights!r}: choose one of {', '.join(WEIGHTS)}")
    if refine_method not in REFINE_METHODS:
        raise SolverError(f"unknown refine method {refine_method!r}: choose one of "
                          f"{', '.join(REFINE_METHODS)}")
    terms = parse_terms(remove)
    scan = Scan.from_fieldmap(field)
    grid = ApertureGrid(scan.D, N)
    if rim is not None:
        if solver == "fft":
            raise SolverError("the fft solver works on the enclosing square and cannot use rim "
                              "targets; choose direct, multigrid, sor or gauss-seidel")
        boundary.check_targets(rim, grid.a)
    n_rows = usable_rows(scan.sphere, scan.F, scan.D)
    scale = _power_scale(scan.intensity, scan, n_rows) if gain == "power" else 1.0
    fa, noise_v, noise_source = _measured_fa(scan, scale, gain, n_rows)
    missing = int(np.count_nonzero(~np.isfinite(fa[:n_rows])))
    inverse = LinearInverse(scan, grid, solver, iterations=iterations, omega=omega, tol=tol,
                            targets=rim, max_harmonics=max_harmonics)
    chosen = choose_model(scan.attrs, refine_iterations, model, forward, device)
    if refine_method == "gauss-newton" and refine_iterations and not chosen.wave:
        raise SolverError(f"gauss-newton needs a wave model (po or po+ptd); the refinement's "
                          f"model is {chosen.name!r}")
    weights = ("amplitude" if chosen.wave else "none") if weights == "auto" else weights
    if weights == "amplitude":
        inverse.weight = amplitude_weight(scan.intensity_ideal, scan.sphere, scan.F,
                                          str(scan.attrs.get("sampling", "centre")))
    delta = inverse.solve(fa)
    linear_info = inverse.info
    setup = refinement_setup(inverse, chosen, refine_iterations, fit_gain=gain == "power",
                             progress=progress)
    delta, history = refine(delta, fa, scan.sphere, scan.F, scan.D, grid, n_rows,
                            setup.correct, refine_iterations, setup.forward, device,
                            weight=inverse.weight, fit_gain=setup.fit_gain,
                            progress=setup.progress)
    gain_factor = history.gain_factor[-1] if history.gain_factor else 1.0
    method, why = choose_method(refine_method, setup, scan, refine_iterations)
    gn_report = None
    if method == "gauss-newton":
        delta, gn_report = refine_gauss_newton(
            delta, fa, inverse, setup.forward, inverse.weight if inverse.weight is not None
            else np.ones_like(fa), n_rows, noise_v, gain_factor, setup.fit_gain, gauss_newton,
            setup.progress, log)
        gain_factor = gn_report.gain_factor
    std = None
    if scan.intensity_std is not None and uncertainty_samples > 0:
        std = _monte_carlo_std(scan, inverse, gain, uncertainty_samples, seed)
    delta_out, coef = remove_terms(grid, delta, terms, scan.F)
    attrs = {
        "solver": solver, "solver_iterations": linear_info.iterations,
        "solver_residual": linear_info.residual, "solver_converged": linear_info.converged,
        "boundary": inverse.describe_boundary(),
        "harmonic_part": "fixed by rim targets" if rim is not None else "unobservable",
        "harmonic_observable": rim is not None,
        "removed_terms": ",".join(terms) or "none",
        "refine_iterations": refine_iterations,
        "refine_model": setup.model,
        "refine_model_choice": setup.choice,
        "refine_method": "defect correction with Anderson acceleration; forward model: "
                         + setup.description,
        "refine_preconditioner": setup.preconditioner,
        "refine_gain_factor": ",".join(f"{v:.9f}" for v in history.gain_factor) or "none",
        "weights": "amplitude: FA times sqrt(I_ideal / I_GO) per sphere cell (1 for GO data)"
                   if weights == "amplitude" else "none",
        "refine_update_rms_m": ",".join(f"{v:.3e}" for v in history.update_rms),
        "refine_misfit_rms": ",".join(f"{v:.3e}" for v in history.misfit_rms),
        "refine_seconds": history.seconds,
        "gain_mode": gain, "gain": scale * gain_factor,
        "gain_source": "GO power balance, then fitted with the surface by the wave refinement"
                       if setup.fit_gain and history.gain_factor else
                       "GO power balance (deformed and ideal send equal power)" if gain == "power"
                       else "none (trusted)",
        "noise_relative_std": float(np.sqrt(noise_v)), "noise_source": noise_source,
        "noise_bias": "removed: FA -> (1 + FA) / (1 + v) - 1" if gain == "power" else
                      "removed: FA -> (1 + FA) / (1 + v/2) - 1 (noise symmetric in dB)",
        "samples_missing": missing,
        "missing_samples": "filled by least-squares Laplacian inpainting on the (theta, phi) "
                           "grid",
        "theta_last_used_deg": float(np.degrees(inverse.coverage.theta_last)),
        "theta_rim_deg": float(np.degrees(inverse.coverage.theta_rim)),
        "rms_definition": f"over the {grid.n_inside} grid points inside r < D/2",
        "focal_length": scan.F, "diameter": scan.D, "sphere_radius": scan.R,
        "data_method": str(scan.attrs.get("method", "")),
        "data_frequency_hz": float(scan.attrs.get("frequency_hz", 0.0)),
    }
    attrs.update(report_attrs(gn_report, why))
    for name, value in coef.items():
        attrs[f"removed_{name}"] = value
    truth_map = _truth_map(truth, scan, grid)
    if truth_map is not None:
        M = metrics.peak_to_peak(grid, truth_map)
        attrs["rms_before_removal_m"] = metrics.rms_error(grid, delta, truth_map)
        truth_map, _ = remove_terms(grid, truth_map, terms)
        attrs["rms_m"] = metrics.rms_error(grid, delta_out, truth_map)
        attrs["rrms"] = attrs["rms_m"] / M
        attrs["truth_peak_to_peak_m"] = M
    attrs["time_s"] = time.perf_counter() - start
    return surfacemap(grid, delta_out, attrs, truth=truth_map, deformation_std=std)


def _power_scale(intensity, scan: Scan, n_rows: int) -> float:
    """The scan's scale from GO power conservation, missing samples filled first.

    A missing sample would drop its cell from both power sums and bias the ratio by its FA;
    inside the usable rows it takes the inpainted ratio I / I_ideal, beyond them the ideal.
    """
    ideal = scan.intensity_ideal
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(ideal > 0, intensity / ideal, np.nan)
    ratio[:n_rows], _ = fill_missing(ratio[:n_rows], n_rows)
    filled = np.where(np.isfinite(intensity), intensity,
                      np.where(np.isfinite(ratio), ratio, 1.0) * ideal)
    return power_gain(filled, ideal, scan.sphere.cell_area())


def _measured_fa(scan: Scan, scale: float, gain: str, n_rows: int):
    """FA of the scan after the gain, with the noise bias removed; and the noise variance used."""
    fa = intensity_ratio_fa(scan.intensity / scale, scan.intensity_ideal)
    if scan.intensity_std is not None:
        v, source = stated_noise_variance(scan.intensity, scan.intensity_std, n_rows), \
            "intensity_std"
    else:
        v, source = noise_variance(fa, n_rows), "estimated from second differences along phi"
    return debias(fa, v if gain == "power" else 0.5 * v), v, source


def _truth_map(truth, scan: Scan, grid: ApertureGrid):
    if isinstance(truth, str):
        if truth != "scene":
            raise SolverError(f"truth must be a callable, an array or 'scene', got {truth!r}")
        truth = _truth_from_scene(scan.attrs)
    if truth is None:
        return None
    if callable(truth):
        X, Y = grid.XY
        return grid.masked(np.asarray(truth(X, Y), dtype=np.float64))
    arr = np.asarray(truth, dtype=np.float64)
    if arr.shape != (grid.N, grid.N):
        raise SolverError(f"truth has shape {arr.shape}, the grid is {(grid.N, grid.N)}")
    return grid.masked(arr)


def _monte_carlo_std(scan: Scan, inverse: LinearInverse, gain: str, samples: int,
                     seed: int) -> NDArray[np.float64]:
    """Std (m) of the linear solution under Gaussian intensity noise of ``intensity_std``.

    The inversion is linear in FA and FA is smooth in the intensity, so the linear solve's
    spread is the refined map's spread to first order.
    """
    rng = np.random.default_rng(seed)
    sigma = np.where(np.isfinite(scan.intensity_std), scan.intensity_std, 0.0)
    draws = []
    rim = inverse.rim
    for _ in range(samples):
        noisy = scan.intensity + sigma * rng.standard_normal(sigma.shape)
        c = _power_scale(noisy, scan, inverse.coverage.n_rows) if gain == "power" else 1.0
        inverse.rim = boundary.zero_rim(inverse.grid.a)
        fa = intensity_ratio_fa(noisy / c, scan.intensity_ideal)
        draws.append(inverse.solve(fa))
    inverse.rim = rim
    return np.std(np.stack(draws), axis=0, ddof=1)
