"""The inversion pipeline: FieldMap (intensity on the sphere) -> SurfaceMap (delta on the aperture).

Frame and units (docs/physics.md): sphere angles in rad, aperture x, y and delta in m.

Steps, each a function of what the previous ones returned: gain (power ratio or none) -> FA
on the sphere with the noise bias removed (:func:`measured_fa`) -> the linear answer
(:class:`solver.linear.LinearInverse`: resample to the aperture grid, Laplacian(delta) = FA / G
on the disk with rim values zero or fitted to rim targets) -> model-based refinement
(``refine_iterations`` iterations of a forward model: GO, or PO / PO+PTD for wave data, chosen
from the FieldMap's ``method`` unless the caller names one) -> optionally Gauss-Newton on the
wave model's exact Jacobian (``refine_method``, :mod:`solver.gauss_newton`) -> the noise's
spread (Monte Carlo, when the scan states its noise) -> optional removal of piston, tilt and
focus -> RMS / RRMS against the truth when it is known -> SurfaceMap with every choice
recorded (:mod:`solver.record`). The settings travel as one frozen :class:`InvertOptions`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from raysim.errors import FieldMapError
from raysim.maps.surfacemap import surfacemap
from raysim.progress import Progress
from solver import boundary
from solver.aperture import ApertureGrid, solver_grid
from solver.central import CentralMode, central_mode_of, hole_radius
from solver.equation import (
    debias,
    intensity_ratio_fa,
    noise_variance,
    power_gain,
    stated_noise_variance,
)
from solver.errors import SolverError
from solver.fit import remove_terms
from solver.forward import Forward
from solver.gainmode import (
    GainChoice,
    GainEstimate,
    MeasuredFA,
    check_trusted_scale,
    estimate_gain,
    refocus_mode,
    resolve_gain,
)
from solver.gauss_newton import (
    GaussNewtonOptions,
    GaussNewtonReport,
    choose_method,
    refine_gauss_newton,
    report_attrs,
)
from solver.linear import MAX_INCIDENCE, LinearInverse, LinearSolution, Scan
from solver.nonlinear import RefineHistory, refine
from solver.options import (
    DEFAULT_N,
    DEFAULT_REFINE,
    DEFAULT_SOLVER,
    WEIGHTS,
    InvertOptions,
)
from solver.record import (
    NOISE_WARNING_FLOOR,
    Outcome,
    accuracy_attrs,
    fit_attrs,
    hole_attrs,
    map_rms,
    noise_spread_attrs,
    rim_attrs,
    ring_attrs,
    sampling_attrs,
    saturation_attrs,
    surface_attrs,
)
from solver.refinement import ModelChoice, RefinementSetup, choose_model, refinement_setup
from solver.resample import cap_rows, usable_rows
from solver.rimimage import rim_image_shift, rows_clear_of_rim
from solver.unobservable import Unobservable, unobservable
from solver.wave import amplitude_weight

__all__ = ["DEFAULT_N", "DEFAULT_REFINE", "DEFAULT_SOLVER", "MAX_INCIDENCE", "WEIGHTS",
           "InvertOptions", "LinearInverse", "MeasuredFA", "Scan", "invert", "measured_fa"]


def invert(field: xr.Dataset, *, solver: str = DEFAULT_SOLVER, N: int = DEFAULT_N,
           rim: boundary.RimTargets | None = None, remove: str | Sequence[str] | None = None,
           refine_iterations: int = DEFAULT_REFINE, gain: str = "auto",
           iterations: int | None = None, omega: float | None = None, tol: float = 1e-10,
           truth: Callable | NDArray | str | None = "scene", forward: Forward | None = None,
           device: str | None = "cpu", uncertainty_samples: int = 32, seed: int = 0,
           max_harmonics: int = boundary.MAX_HARMONICS, model: str | None = None,
           weights: str = "auto", progress: Progress | None = None,
           refine_method: str = "defect", gauss_newton: GaussNewtonOptions | None = None,
           log: Callable[[str], None] | None = None, radiator: str = "fast",
           radiator_tol: float = 1e-6, options: InvertOptions | None = None) -> xr.Dataset:
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
    gain : ``known`` trusts the scan's scale; ``power`` estimates it from the total power and
        reports the map with the unobservable delta_c mode removed (:mod:`solver.gainmode`);
        ``auto`` (default) is ``known`` for simulated data, ``power`` for a measured scan;
        ``none`` is the former name of ``known``.
    iterations, omega, tol : settings of the iterative solvers (see :func:`solve_poisson`).
    truth : None, a callable delta(x, y) (m), an (N, N) array (m), or ``"scene"`` (the
        FieldMap's scene deformation when it carries a scene).
    forward : the refinement's forward model (a :class:`solver.forward.ForwardModel`, or a
        plain function, see :mod:`solver.forward`); None builds the one ``model`` names. A
        model keeps the ideal reflector's map, so passing one model to several inversions of
        one scan geometry computes it once.
    device : Warp device of the forward model (``cpu`` or ``cuda``).
    uncertainty_samples : Monte Carlo draws for ``deformation_std`` and ``deformation_noise_draws``
        (under the stated intensity_std, or under the noise estimated from the scan where it
        spreads the map by a tenth of its RMS or more; at least 2, 0 for none).
    seed : random seed of the Monte Carlo draws.
    max_harmonics : highest Fourier order of the rim fit.
    model : the refinement's forward model, one of :data:`solver.forward.MODELS` (``go``,
        ``po``, ``po+ptd``); None picks the one that made the data (FieldMap ``method``: GO for
        GO data, PO for PO data, GO for a measured scan). A wave model brings its own
        preconditioner (:class:`solver.wave.WaveCorrection`) and, unless ``gain="none"``,
        fits the scan's scale with the surface when the gain is estimated.
    weights : ``amplitude`` multiplies FA (and every refinement misfit) by sqrt(I_ideal /
        I_GO) per sphere cell, which keeps wave data's response near GO's in the dark rings
        of the diffraction pattern (:func:`solver.wave.amplitude_weight`; 1 for GO data);
        ``none`` uses FA as the paper does; ``auto`` (default) weights when the refinement
        runs a wave model, so the linear answer (refine 0) stays the paper's equation.
    progress : optional ``progress(stage, fraction)`` of the refinement (0..1).
    refine_method : ``defect`` (the defect correction alone, the default), ``gauss-newton``
        (then Gauss-Newton with the PO / PO + PTD model's exact Jacobian,
        :mod:`solver.gauss_newton`) or ``auto`` (Gauss-Newton where it is affordable and the
        model allows it: :func:`solver.gauss_newton.choose_method`).
    gauss_newton : :class:`solver.gauss_newton.GaussNewtonOptions` (None: the defaults).
    radiator, radiator_tol : how a PO / PO + PTD model sums its elements' fields, in its
        fields and its Jacobian's products: ``fast`` (default: the multilevel sum where it is
        cheaper, relative RMS accuracy ``radiator_tol``) or ``direct`` (the reference sum).
    log : optional ``log(line)`` of each Gauss-Newton step (misfit, update, time).
    options : all the settings above at once; when given, it replaces the keyword settings
        (``truth``, ``progress`` and ``log`` stay separate: they are not settings of the method).
    """
    start = time.perf_counter()
    opts = options if options is not None else InvertOptions(
        solver=solver, N=N, rim=rim, remove=remove, refine_iterations=refine_iterations,
        gain=gain, iterations=iterations, omega=omega, tol=tol, forward=forward, device=device,
        uncertainty_samples=uncertainty_samples, seed=seed, max_harmonics=max_harmonics,
        model=model, weights=weights, refine_method=refine_method, gauss_newton=gauss_newton,
        radiator=radiator, radiator_tol=radiator_tol)
    if not isinstance(field, xr.Dataset):  # a path or a DataArray failed deep in xarray
        raise FieldMapError(f"invert takes a FieldMap, an xarray.Dataset (raysim.load_fieldmap("
                            f"path) reads one), not {type(field).__name__}")
    scan = Scan.from_fieldmap(field)
    hole = scan.check_coverage()
    grid = solver_grid(scan.D, opts.N)
    if opts.rim is not None:
        boundary.check_targets(opts.rim, grid.a)
    gain = resolve_gain(opts.gain, str(scan.attrs.get("method", "")))
    chosen = choose_model(scan.attrs, opts.refine_iterations, opts.model, opts.forward, opts.device,
                          scan.obstacles, opts.radiator, opts.radiator_tol)
    choice = choose_method(opts.refine_method, chosen.forward, scan, opts.refine_iterations,
                           opts.gauss_newton)
    method, why = choice.method, choice.why
    if choice.inner is not None:  # auto: the steps and LSQR iterations that fit its budget
        opts = replace(opts, gauss_newton=choice.applied(opts.gauss_newton))
    weighted = opts.weights == "amplitude" or (opts.weights == "auto" and chosen.wave)
    solved = _solve(scan, grid, gain, chosen, weighted, opts, progress)
    # rows the map's rim image crosses are lit in part: solve again without them
    shift = rim_image_shift(grid, solved.delta, scan.F, scan.D, scan.R)
    n_all = solved.data.n_rows
    clear = rows_clear_of_rim(scan.sphere, scan.F, scan.D, n_all, shift)
    if clear < n_all:
        first = solved.history
        scan = scan.first_rows(clear)
        solved = _solve(scan, grid, gain, chosen, weighted, opts, progress)
        # the first solve's model runs and time are the inversion's too (its misfits are not:
        # they describe another map on other rows); refine_forward_runs counted only the second
        solved.history.evaluations += first.evaluations
        solved.history.seconds += first.seconds
    data, inverse, linear, setup = solved.data, solved.inverse, solved.linear, solved.setup
    delta, history = solved.delta, solved.history
    gn = None
    if method == "gauss-newton":
        delta, gn = _gauss_newton(inverse, delta, data, setup, history, opts, log)
    refined = setup.forward is not None and opts.refine_iterations > 0
    mode = delta_c_mode(inverse, refined) if data.gain.estimated else None
    central = _central_mode(inverse, delta, data, setup, opts)
    # delta_c and the central mode overlap on the annulus: removed by one joint fit
    unseen = unobservable(grid, {"central": central.shape if central is not None else None,
                                 "delta_c": mode}, central.r_h if central is not None else None)

    def output(delta):
        """A map as it is written: the unobservable shapes and the requested terms removed."""
        removed = {}
        if unseen is not None:
            delta, removed = unseen.remove(grid, delta)
        if central is not None:
            delta = central.blank(grid, delta)
        return delta, removed

    delta, removed = output(delta)
    delta_c = removed.get("delta_c", 0.0)
    delta_out, coef = remove_terms(grid, delta, opts.terms, scan.F)
    # the noise's spread is measured on the linear solve: it is weighed against the smaller of
    # the linear map and the refined one, since in noise the refinement fits the noise's
    # nonlinear part (a trusted gain, 0.5 dB per reading: the refined map 29 mm off, 3.4
    # times the spread, against the linear map's 9.1 mm, and the refined map's RMS was large
    # enough to hide the warning)
    size = map_rms(delta_out)
    size_linear = map_rms(remove_terms(grid, output(linear.delta)[0], opts.terms, scan.F)[0])
    of_map = "the map's own RMS" if size <= size_linear else "the linear map's RMS"
    size = min(size, size_linear)
    stated = scan.intensity_std is not None and np.any(np.isfinite(scan.intensity_std[:data.n_rows]))
    spread = float("nan")
    draws = None
    if stated and opts.uncertainty_samples > 1:  # an all-NaN std states nothing (measured_fa)
        draws = monte_carlo_draws(scan, inverse, data, opts.uncertainty_samples, opts.seed, unseen)
    elif not stated:
        draws = noise_screen(scan, inverse, data, opts, unseen, central, size)
    std = noise_draws = None
    if draws is not None:
        # kept, less their mean, for the commands (solver.correction): the noise is correlated
        # across the dish, which no per-point std carries
        noise_draws = draws - draws.mean(axis=0)
        if central is not None:
            noise_draws = np.stack([central.blank(grid, d) for d in noise_draws])
        std = np.std(noise_draws, axis=0, ddof=1)
        spread = float(np.sqrt(np.nanmean(std**2)))
    outcome = Outcome(scan, grid, inverse, linear, data, setup, history, weighted, coef,
                      gn.gain_factor if gn is not None else None, delta_c, mode)
    attrs = surface_attrs(opts, outcome)
    attrs.update(rim_attrs(shift, n_all - clear, scan.sphere))
    attrs.update(hole_attrs(hole))
    attrs.update(ring_attrs(scan))
    attrs.update(sampling_attrs(scan))
    attrs.update(saturation_attrs(scan, data.n_rows))
    attrs.update(report_attrs(gn, why))
    attrs.update(noise_spread_attrs(spread, bool(stated), data, size, of_map))
    if gn is not None and gn.misfit_rms:  # the map is Gauss-Newton's: its misfit says the fit
        attrs.pop("refine_warning", None)
        attrs.update(fit_attrs(data, gn.misfit_rms[-1]))
    if central is not None:
        attrs.update(central.attrs(removed["central"]))
    if unseen is not None:
        attrs.update(unseen.attrs(grid))
    if scan.blocked is not None:
        attrs["samples_blocked"] = int(scan.blocked[:data.n_rows].sum())
    truth_map = truth_on_grid(truth, scan, grid)
    if truth_map is not None:
        accuracy, truth_map = accuracy_attrs(grid, delta, delta_out, truth_map, opts.terms, unseen)
        attrs.update(accuracy)
    attrs["time_s"] = time.perf_counter() - start
    return surfacemap(grid, delta_out, attrs, truth=truth_map, deformation_std=std,
                      noise_draws=noise_draws)


@dataclass(frozen=True)
class _Solved:
    """The linear answer to a scan and its refinement, with what made them."""

    data: MeasuredFA
    inverse: LinearInverse
    linear: LinearSolution
    setup: RefinementSetup
    delta: NDArray[np.float64]
    history: RefineHistory


def _solve(scan: Scan, grid: ApertureGrid, gain: GainChoice, chosen: ModelChoice, weighted: bool,
           opts: InvertOptions, progress: Progress | None) -> _Solved:
    """The scan's FA, its linear answer and the model-based refinement of it."""
    data = measured_fa(scan, gain)
    weight = amplitude_weight(scan.intensity_ideal, scan.sphere, scan.F,
                              str(scan.attrs.get("sampling", "centre"))) if weighted else None
    inverse = LinearInverse(scan, grid, opts.solver, opts.iterations, opts.omega, opts.tol,
                            opts.rim, opts.max_harmonics, weight)
    linear = inverse.solve(data.fa)
    setup = refinement_setup(inverse, chosen, opts.refine_iterations,
                             fit_gain=data.gain.estimated, progress=progress)
    delta, history = _refine(inverse, linear, data, setup, opts)
    return _Solved(data, inverse, linear, setup, delta, history)


def _refine(inverse: LinearInverse, linear: LinearSolution, data: MeasuredFA,
            setup: RefinementSetup, opts: InvertOptions) -> tuple[NDArray[np.float64], RefineHistory]:
    """The model-based refinement of the linear answer (:func:`solver.nonlinear.refine`)."""
    scan = inverse.scan
    return refine(linear.delta, data.fa, scan.sphere, scan.F, scan.D, inverse.grid, data.n_rows,
                  setup.correct, opts.refine_iterations, setup.forward, opts.device,
                  weight=inverse.weight, fit_gain=setup.fit_gain, progress=setup.progress,
                  noise_variance=data.noise_variance)


def _central_mode(inverse: LinearInverse, delta: NDArray[np.float64], data: MeasuredFA,
                  setup: RefinementSetup, opts: InvertOptions) -> CentralMode | None:
    """The unobservable mode of a blocked centre (:mod:`solver.central`; None without one):
    the refinement model's null shape at ``delta``, or the log mode of a linear answer."""
    scan = inverse.scan
    r_h = hole_radius(scan.blocked, scan.sphere.theta_edges, scan.F)
    refined = opts.refine_iterations > 0 and setup.forward is not None
    observed = np.isfinite(data.fa)
    observed[data.n_rows:] = False
    return central_mode_of(r_h, inverse.grid, delta, setup.forward if refined else None,
                           setup.correct, scan.sphere, scan.F, scan.D, observed, inverse.weight,
                           setup.progress)


def _gauss_newton(inverse: LinearInverse, delta: NDArray[np.float64], data: MeasuredFA,
                  setup: RefinementSetup, history: RefineHistory, opts: InvertOptions,
                  log: Callable[[str], None] | None
                  ) -> tuple[NDArray[np.float64], GaussNewtonReport]:
    """Gauss-Newton from the defect correction's answer and scale factor
    (:func:`solver.gauss_newton.refine_gauss_newton`)."""
    weight = inverse.weight if inverse.weight is not None else np.ones_like(data.fa)
    gain_factor = history.gain_factor[-1] if history.gain_factor else 1.0
    return refine_gauss_newton(delta, data.fa, inverse, setup.forward, weight, data.n_rows,
                               data.noise_variance, gain_factor, setup.fit_gain,
                               opts.gauss_newton, setup.progress, log)


def delta_c_mode(inverse: LinearInverse, refined: bool) -> NDArray[np.float64]:
    """The map's response (m) to a unit FA offset: the shape an unknown gain leaves open.

    The linear answer's is its own solve of FA = 1 (weighted like the data); a model-based
    answer's is the refocus of :func:`solver.gainmode.refocus_mode`. With rim targets the
    rim fit's response to the shape is part of it (targets inside the rim see it).
    """
    grid = inverse.grid
    if refined:
        base = np.where(grid.mask, refocus_mode(grid, inverse.scan.F, inverse.scan.R), 0.0)
    else:
        ones = np.ones_like(inverse.scan.intensity_ideal)
        base = inverse.poisson(inverse.to_aperture(ones if inverse.weight is None
                                                   else inverse.weight))
    if inverse.targets is not None:
        base = base + inverse.rim_update(base) - inverse.rim_update(np.zeros_like(base))
    return grid.masked(base)


def measured_fa(scan: Scan, gain: GainChoice) -> MeasuredFA:
    """FA of the scan after the gain (trusted or estimated), with the noise bias removed."""
    n_rows = usable_rows(scan.sphere, scan.F, scan.D)
    stated = scan.intensity_std
    if stated is not None and not np.any(np.isfinite(stated[:n_rows])):
        stated = None  # one reading per point: no spread stated, the noise is estimated instead
    if stated is not None:
        v = stated_noise_variance(scan.intensity, stated, n_rows)
        source = "intensity_std"
    else:
        # FA's differences grow as 1 / the readings' scale: with the gain estimated they are
        # taken on the readings brought to the ideal's scale by their power balance, else a
        # scan read in W (1e-9 of the ideal) had a noise variance 1e17 times its own
        c0 = (power_gain(scan.intensity, scan.intensity_ideal, scan.sphere.cell_area())
              if gain.estimated else 1.0)
        v = noise_variance(intensity_ratio_fa(scan.intensity / c0, scan.intensity_ideal), n_rows)
        source = "estimated from second differences along phi"
    if not gain.estimated:
        check_trusted_scale(scan.intensity, scan.intensity_ideal, scan.sphere, gain)
    estimate = (estimate_gain(scan.intensity, scan.intensity_ideal, scan.sphere, n_rows, v,
                              stated) if gain.estimated
                else GainEstimate(1.0, 0.0, 1.0))
    fa = intensity_ratio_fa(scan.intensity / estimate.scale, scan.intensity_ideal)
    # with the polar cap's cells when the scan starts short of the pole (filled likewise)
    missing = int(np.count_nonzero(~np.isfinite(fa[:n_rows]))) + cap_rows(scan.sphere) * scan.sphere.n_phi
    return MeasuredFA(debias(fa, v if gain.estimated else 0.5 * v), gain, estimate, v, source,
                      n_rows, missing)


def _truth_from_scene(attrs: dict) -> Callable | None:
    """The deformation of the scene a FieldMap carries (None without one, or if it no longer
    parses: :func:`raysim.scene.scene.scene_of`); for a mesh scene, the mesh's own departure
    from its ideal (:func:`mesh_truth`)."""
    from raysim.scene.scene import scene_of

    scene = scene_of(attrs)
    if scene is None:
        return None
    return scene.deformation if scene.dish.mesh is None else mesh_truth(scene, attrs)


def mesh_truth(scene, attrs: dict | None = None) -> Callable | None:
    """delta(x, y) (m, along z) of a mesh scene: the deformed reflector's surface height less
    its ideal's at the same (x, y), as the engines simulate them (the fitted paraboloid plus
    each file's departure, :mod:`raysim.surface.departure`, and the scene's own deformation
    on top). Heights at one (x, y), not vertex by vertex: nodes that slid along the surface
    (an FEM output's) are no deformation. None when the mesh no longer loads, or departs from
    its ideal by another RMS than the FieldMap's ``mesh_departure_rms_m`` (another file under
    its name): the truth is then unknown (taking the scene's zero deformation made every
    mesh's map read as its own error)."""
    from raysim.errors import RaysimError
    from raysim.surface.mesh import mesh_departure_rms, reflectors_for

    try:
        ideal, deformed = reflectors_for(scene)
    except (RaysimError, OSError):
        return None
    recorded = (attrs or {}).get("mesh_departure_rms_m")
    if recorded is not None and not np.isclose(mesh_departure_rms(ideal, deformed), float(recorded),
                                               rtol=1e-6, atol=1e-12):
        return None  # another file now has the name the scene gives: not the mesh simulated

    from scipy.spatial import cKDTree

    xy = ideal.vertices[:, :2]
    edges = xy[ideal.faces] - xy[np.roll(ideal.faces, 1, axis=1)]
    reach = float(np.median(np.hypot(edges[..., 0], edges[..., 1])))
    tree = cKDTree(xy)

    def delta(x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        # each point on the face of its nearest vertex, the scene's deformation finding its own
        # panels; a point over a triangle's edge away from every vertex (in a wide gap, beyond
        # the rim) takes the nearest vertex's value, not the surfaces' continuation
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        distance, nearest = tree.query(np.column_stack([x.ravel(), y.ravel()]))
        far = distance > reach
        px, py = x.ravel().copy(), y.ravel().copy()
        px[far], py[far] = xy[nearest[far], 0], xy[nearest[far], 1]
        return (deformed.surface.height(px, py) - ideal.surface.height(px, py)).reshape(x.shape)

    return delta


def truth_on_grid(truth, scan: Scan, grid: ApertureGrid) -> NDArray[np.float64] | None:
    """The true delta (m) on the aperture grid, NaN outside; None when it is not known."""
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


def noise_screen(scan: Scan, inverse: LinearInverse, data: MeasuredFA, opts: InvertOptions,
                 unseen: Unobservable | None, central: CentralMode | None,
                 size: float) -> NDArray[np.float64] | None:
    """The Monte Carlo draws (samples, N, N) (m) of the map under the noise estimated from
    the scan (no ``intensity_std`` stated: ``data.noise_variance``) where that noise spreads
    a map of RMS ``size`` (m) by a share worth measuring; None where it does not.

    :data:`SCREEN_DRAWS` draws first (a rough figure: the spread lies mostly in a few slow
    shapes); where they reach :data:`NOISE_SCREEN` of the map's RMS the whole Monte Carlo of
    the stated case measures it, the estimated noise in every cell, and its draws are the
    map's (the commands' error comes from them). Clean data cost the two draws only (about
    0.1 s at 256 points).
    """
    if opts.uncertainty_samples <= 1 or not data.noise_variance > 0:
        return None
    rough = monte_carlo_std(scan, inverse, data, SCREEN_DRAWS, opts.seed, unseen)
    if central is not None:
        rough = central.blank(inverse.grid, rough)
    if np.sqrt(np.nanmean(rough**2)) < NOISE_SCREEN * max(size, NOISE_WARNING_FLOOR):
        return None
    return monte_carlo_draws(scan, inverse, data, opts.uncertainty_samples, opts.seed, unseen)


#: draws of the screen, and the share of the map's RMS their rough spread must reach for the
#: whole Monte Carlo to measure it: a fifth of the warning's share (record.NOISE_SHARE_WARNING),
#: room for the two draws' scatter
SCREEN_DRAWS = 2
NOISE_SCREEN = 0.1


def monte_carlo_std(scan: Scan, inverse: LinearInverse, data: MeasuredFA, samples: int,
                    seed: int, unseen: Unobservable | None = None) -> NDArray[np.float64]:
    """Std (m) of the linear solution over :func:`monte_carlo_draws`."""
    return np.std(monte_carlo_draws(scan, inverse, data, samples, seed, unseen), axis=0, ddof=1)


def monte_carlo_draws(scan: Scan, inverse: LinearInverse, data: MeasuredFA, samples: int,
                      seed: int, unseen: Unobservable | None = None) -> NDArray[np.float64]:
    """Linear solutions (samples, N, N) (m) under Gaussian intensity noise of ``intensity_std``
    (the noise estimated from the scan, ``data.noise_variance``, where it states none).

    The inversion is linear in FA and FA is smooth in the intensity, so the linear solve's
    spread is the refined map's spread to first order. Each draw gets the data's treatment:
    the scale estimated again when the gain is, and the ``unseen`` shapes (delta_c, the
    central mode: :mod:`solver.unobservable`) removed as from the map.
    """
    rng = np.random.default_rng(seed)
    # a cell without a stated spread has the scan's noise, not none: NaN read as 0 on every
    # other phi column made the stated spread 62 um where it is 93 um
    typical = np.sqrt(data.noise_variance) * np.abs(np.nan_to_num(scan.intensity))
    stated = (scan.intensity_std if scan.intensity_std is not None
              else np.full_like(typical, np.nan))
    sigma = np.where(np.isfinite(stated), stated, typical)
    draws = []
    for _ in range(samples):
        noisy = scan.intensity + sigma * rng.standard_normal(sigma.shape)
        c = (estimate_gain(noisy, scan.intensity_ideal, scan.sphere, data.n_rows,
                           data.noise_variance).scale if data.gain.estimated else 1.0)
        delta = inverse.solve(intensity_ratio_fa(noisy / c, scan.intensity_ideal)).delta
        if unseen is not None:
            delta, _ = unseen.remove(inverse.grid, delta)
        draws.append(delta)
    return np.stack(draws)
