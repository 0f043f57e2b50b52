"""Gauss-Newton refinement with the wave model's exact Jacobian (PO / PO + PTD).

Frame and units (docs/physics.md): sphere cells (theta, phi in rad), the aperture grid (x, y,
delta in m), FA dimensionless.

The data misfit is the refinement's (:mod:`solver.nonlinear`): on the usable sphere cells,

    r(delta, gamma) = w [(1 + FA_measured) gamma - I0_model / I_model(delta)],

with w the amplitude weight and gamma the scan's scale (fitted when the gain is not trusted).
Each step linearises the model exactly (:class:`solver.jacobian.WaveJacobian`: d(I0 / I) =
-(I0 / I^2) dI, dI = 2 Re(conj(E) . dE), the JVP and its adjoint each about one PO radiation)
and solves the linear least-squares problem min |r + J d| matrix-free with LSQR (Paige &
Saunders, ACM TOMS 8, 43, 1982), right-preconditioned by the GO Poisson solve: the unknown is
y = G Laplacian(d) on the grid points inside the aperture (d = M y, zero on the rim), in which
the GO part of J is close to a resampling, so LSQR's first iterations take the well-determined
directions. Regularisation is by iteration (the discrepancy principle, Morozov 1966): LSQR
stops as soon as the linearised residual is no larger than the noise the data carry,
|r + J d|^2 <= sigma^2 sum w^2 (1 + ``sigmas`` sqrt(2 / n)) over the n cells compared: the
chi-square expectation of pure noise plus ``sigmas`` of its standard deviations, sigma the
samples' relative noise (stated by the scan or estimated from second differences along
phi); directions the data do not see are never
entered (LSQR's iterates stay in the range of the preconditioned transpose), so nothing is
added where the data carry no information. A step that does not lower the misfit is halved
(up to ``backtrack`` times); the outer loop stops when the misfit reaches the noise level,
stalls, or after ``iterations`` steps. Rim targets are kept by the harmonic rim update of the
linear inverse at each step.

Coarse steps (``coarse``, the first steps of a run) solve their linear problem on one sphere cell
in eight (every 2nd theta ring and every 4th phi column, :data:`COARSE_STRIDE`): a sketch of J's
rows, in the spirit of sub-sampled Newton methods (Roosta-Khorasani & Mahoney, Math. Program.
174, 293, 2019). Each JVP and VJP then radiates to those cells only, an eighth of the cost; the
step is still accepted or halved on the misfit over all cells, and the discrepancy bound is the
subset's own. The last steps use every cell, so the answer is the full data's: the coarse steps
only bring the estimate near it, where on the paper's 90 x 360 grid each full LSQR iteration
costs eight of theirs.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from raysim.progress import Progress
from solver.equation import misfit_noise_rms
from solver.errors import SolverError
from solver.forward import ForwardModel, WaveForward, active_runner
from solver.resample import modelled_rows

STALL = 0.995      # a step that lowers the misfit by less than 0.5 % ends the loop
MAX_STEPS = 50     # outer Gauss-Newton steps a run may ask for
MAX_INNER = 1000   # LSQR iterations per step a run may ask for
COARSE_STRIDE = (2, 4)  # a coarse step's cells: every 2nd theta ring, every 4th phi column


@dataclass(frozen=True)
class GaussNewtonOptions:
    """Settings: outer steps, LSQR iterations per step, the discrepancy principle's tolerance
    (chi-square standard deviations above the noise's expectation), backtracking halvings,
    and how many of the first steps are coarse (their LSQR on one cell in eight,
    :data:`COARSE_STRIDE`; module docstring)."""

    iterations: int = 3
    inner: int = 60
    sigmas: float = 2.0
    backtrack: int = 2
    coarse: int = 0

    def __post_init__(self) -> None:
        for name, value, lo, hi in (("steps", self.iterations, 1, MAX_STEPS),
                                    ("LSQR iterations per step", self.inner, 1, MAX_INNER),
                                    ("backtracking halvings", self.backtrack, 0, 10),
                                    ("coarse steps", self.coarse, 0, MAX_STEPS)):
            if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
                raise SolverError(f"Gauss-Newton {name} must be an integer in {lo}..{hi}, "
                                  f"got {value!r}")
        if not (isinstance(self.sigmas, (int, float)) and 0.0 <= self.sigmas <= 100.0):
            raise SolverError(f"Gauss-Newton sigmas must be a number in 0..100, got {self.sigmas!r}")
        if self.coarse >= self.iterations:
            raise SolverError(f"Gauss-Newton coarse steps ({self.coarse}) must leave at least "
                              f"one step on all cells ({self.iterations} steps)")


@dataclass
class GaussNewtonReport:
    """Per outer step: weighted misfit RMS, update RMS (m), LSQR iterations, step factor,
    seconds since the start; the noise floor of the rule and why the loop stopped."""

    misfit_rms: list[float] = field(default_factory=list)
    update_rms: list[float] = field(default_factory=list)
    inner_iterations: list[int] = field(default_factory=list)
    step_factor: list[float] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    coarse: list[bool] = field(default_factory=list)
    gain_factor: float = 1.0
    noise_rms: float = 0.0
    stopped: str = ""
    jvp_calls: int = 0
    vjp_calls: int = 0

    def describe(self) -> str:
        coarse = f" ({sum(self.coarse)} coarse)" if any(self.coarse) else ""
        return (f"Gauss-Newton, exact PO Jacobian, LSQR stopped by the discrepancy principle "
                f"(noise {self.noise_rms:.2e}); {len(self.update_rms)} steps{coarse}, inner "
                f"{self.inner_iterations}, stopped: {self.stopped}")


class _Problem:
    """The misfit at one estimate and the preconditioned linear operator of its Jacobian."""

    def __init__(self, jac, fa_measured, I0, weight, rows, gamma, inverse, fit_gain):
        self.jac, self.inverse, self.fit_gain = jac, inverse, fit_gain
        I = jac.intensity
        self.rows = rows                       # boolean (n_theta, n_phi): cells compared
        self.scale_d = np.where(rows, weight * I0 / I**2, 0.0)   # d r / d I = +w I0 / I^2
        self.col_gain = np.where(rows, weight * (1.0 + fa_measured), 0.0)
        r = weight * ((1.0 + fa_measured) * gamma - I0 / I)
        self.r = np.where(rows, r, 0.0)
        grid = inverse.grid
        self.mask = grid.mask
        self.Ginv = 1.0 / inverse.G[grid.mask]

    def misfit_rms(self) -> float:
        return float(np.sqrt(np.sum(self.r**2) / np.count_nonzero(self.rows)))

    def precondition(self, y):
        from solver.poisson import disk_laplacian

        op = disk_laplacian(self.inverse.grid.D, self.inverse.grid.N)
        return op.lu().solve(y * self.Ginv)

    def precondition_T(self, d):
        from solver.poisson import disk_laplacian

        op = disk_laplacian(self.inverse.grid.D, self.inverse.grid.N)
        return op.lu().solve(np.ascontiguousarray(d), trans="T") * self.Ginv

    def operator(self, rows: NDArray[np.bool_]) -> spla.LinearOperator:
        """The preconditioned Jacobian (and gain column) on the cells ``rows`` (a subset of
        the compared cells), its JVP and VJP evaluated there only."""
        n_in = int(np.count_nonzero(self.mask))
        n = n_in + (1 if self.fit_gain else 0)
        m = int(np.count_nonzero(rows))
        self.jac.restrict(None if rows is self.rows else rows)

        def matvec(v):
            dI = self.jac.jvp(self.precondition(v[:n_in]))
            out = self.scale_d * dI
            if self.fit_gain:
                out = out + self.col_gain * v[n_in] * GAIN_UNIT
            return out[rows]

        def rmatvec(u):
            full = np.zeros(rows.shape)
            full[rows] = u
            g = self.precondition_T(self.jac.vjp(self.scale_d * full))
            if self.fit_gain:
                g = np.append(g, GAIN_UNIT * float(np.sum(self.col_gain * full)))
            return g

        return spla.LinearOperator((m, n), matvec=matvec, rmatvec=rmatvec, dtype=np.float64)


GAIN_UNIT = 1e-3  # the scale's unknown in LSQR is gamma steps of 1e-3 (FA-sized)


def refine_gauss_newton(delta0: NDArray[np.float64], fa_measured: NDArray[np.float64],
                        inverse, model, weight: NDArray[np.float64], n_rows: int,
                        noise_variance: float, gamma0: float = 1.0, fit_gain: bool = False,
                        options: GaussNewtonOptions | None = None,
                        progress: Progress | None = None,
                        log: Callable[[str], None] | None = None
                        ) -> tuple[NDArray[np.float64], GaussNewtonReport]:
    """Refine ``delta0`` (m, (N, N)) by Gauss-Newton on the wave model ``model``.

    ``inverse`` is the scan's :class:`solver.invert.LinearInverse` (grid, G, rim targets);
    ``fa_measured`` the gain-corrected FA on the sphere (NaN where missing), ``weight`` the
    per-cell weight of the misfit, ``n_rows`` the usable theta rows, ``noise_variance`` the
    samples' relative intensity variance (the discrepancy principle's noise level),
    ``gamma0`` the starting scale factor. ``progress(stage, fraction)`` and ``log(line)``
    report each step: misfit, update, time.
    """
    from solver.jacobian import WaveJacobian

    options = options or GaussNewtonOptions()
    scan, grid = inverse.scan, inverse.grid
    say = log or (lambda line: None)
    report_progress = progress or (lambda stage, fraction: None)
    start = time.perf_counter()
    I0 = model(scan.sphere, scan.F, scan.D, grid.x, grid.y, None)
    compared = min(n_rows, modelled_rows(scan.sphere, scan.F, scan.D, grid.h))
    rows = np.zeros(fa_measured.shape, dtype=bool)
    rows[:compared] = True
    rows &= np.isfinite(fa_measured) & np.isfinite(weight)
    fa = np.nan_to_num(fa_measured)
    w = np.nan_to_num(weight)
    report = GaussNewtonReport()
    report.noise_rms = misfit_noise_rms(noise_variance, fa_measured, weight, compared)

    def floor_on(cells):
        """The discrepancy principle's bound on |r| over ``cells`` (module docstring)."""
        n = np.count_nonzero(cells)
        return float(np.sqrt(noise_variance * np.sum(w[cells] ** 2)
                             * (1.0 + options.sigmas * np.sqrt(2.0 / n))))

    floor = floor_on(rows)
    coarse_rows = np.zeros_like(rows)
    coarse_rows[::COARSE_STRIDE[0], ::COARSE_STRIDE[1]] = True
    coarse_rows &= rows
    delta = np.array(delta0, dtype=np.float64, copy=True)
    delta = delta + inverse.rim_update(delta)
    gamma = float(gamma0)

    def problem_at(d, g):
        jac = WaveJacobian(model, scan.sphere, scan.F, scan.D, grid, d)
        return _Problem(jac, fa, I0, w, rows, g, inverse, fit_gain)

    prob = problem_at(delta, gamma)
    report.misfit_rms.append(prob.misfit_rms())
    say(f"gauss-newton start: misfit {report.misfit_rms[-1]:.3e} (noise {report.noise_rms:.2e})")
    for it in range(options.iterations):
        norm_r = float(np.linalg.norm(prob.r))
        if norm_r <= floor:
            report.stopped = "misfit at the noise level (discrepancy principle)"
            break
        # a coarse step solves on a subset of the cells (a sketch of the rows of J: each
        # product costs 1/8 of a radiation); its step is still judged on all of them
        coarse = it < options.coarse and np.any(coarse_rows)
        solve = coarse_rows if coarse else rows
        kind = "coarse LSQR" if coarse else "LSQR"
        report_progress(f"gauss-newton {it + 1}/{options.iterations}: {kind}",
                        it / options.iterations)
        rhs = -prob.r[solve]
        sol = spla.lsqr(prob.operator(solve), rhs, atol=0.0,
                        btol=floor_on(solve) / max(float(np.linalg.norm(rhs)), 1e-300),
                        iter_lim=options.inner)
        y, inner = sol[0], int(sol[2])
        n_in = int(np.count_nonzero(grid.mask))
        update = np.zeros_like(delta)
        update[grid.mask] = prob.precondition(y[:n_in])
        dgamma = float(y[n_in]) * GAIN_UNIT if fit_gain else 0.0
        report.jvp_calls += prob.jac.calls["jvp"]
        report.vjp_calls += prob.jac.calls["vjp"]
        factor, accepted = 1.0, None
        for _ in range(options.backtrack + 1):
            trial = delta + factor * update
            trial = trial + inverse.rim_update(trial)
            candidate = problem_at(trial, gamma + factor * dgamma)
            if candidate.misfit_rms() < report.misfit_rms[-1]:
                accepted = (trial, candidate)
                break
            factor *= 0.5
        if accepted is None:
            report.stopped = "no step lowered the misfit"
            break
        delta, prob = accepted
        gamma += factor * dgamma
        report.inner_iterations.append(inner)
        report.step_factor.append(factor)
        report.coarse.append(bool(coarse))
        report.update_rms.append(float(np.sqrt(np.mean((factor * update[grid.mask]) ** 2))))
        report.misfit_rms.append(prob.misfit_rms())
        report.seconds.append(time.perf_counter() - start)
        say(f"gauss-newton {it + 1}: misfit {report.misfit_rms[-1]:.3e}, update "
            f"{report.update_rms[-1] * 1e6:.2f} um (x{factor:g}), {kind} {inner}, "
            f"{report.seconds[-1]:.0f} s")
        if report.misfit_rms[-1] > STALL * report.misfit_rms[-2]:
            report.stopped = "misfit stalled"
            break
    else:
        report.stopped = f"{options.iterations} steps"
    report.gain_factor = gamma
    report_progress("gauss-newton done", 1.0)
    return delta, report


REFINE_METHODS = ("auto", "defect", "gauss-newton")
#: the pair evaluations (direct-sum units, as :func:`model_pairs` counts one radiation) that
#: "auto" lets a whole Gauss-Newton run spend: each LSQR iteration is two radiations. About
#: 10 minutes on two cores, measured on the paper's dish (90 x 360) with the fast radiator:
#: 0.1 GHz (4e7 per radiation), 3 steps x 60 iterations (1.4e10) in 4.2 min; 0.3 GHz (2e8),
#: 2 steps x 46 iterations (3.6e10) in 8.3 min, the defect correction's start included;
#: 0.6 GHz (6.6e8), 1 step x 27 in 9.3 min. Those were 3.6e10 of the units before PO's pairs ran
#: in vector lanes; the fast plan now counts lane pairs, and its estimates of these radiations
#: are 1.16 to 1.22 times the old ones (4.8e7, 2.4e8, 7.9e8), while the JVP's and VJP's pairs,
#: which fill the iterations, then still ran one point at a time: so the same minutes and the
#: same steps were 4.4e10. Re-timed with every sum in lanes (5 December 2026, two cores,
#: ``benchmarks/bench_gauss_newton.py --noise 0 --methods auto``): 0.3 GHz 2 x 46 in 484 s
#: (1.75 % RRMS); with the leaves on grids of their own sizes the estimates fall (2.15e8 and
#: 6.9e8 a radiation): 0.3 GHz 2 x 51 in 453 s (1.66 %), 0.6 GHz 1 x 31 in 504 s (0.76 %); with
#: PO's Gauss orders set by the rule's own error (7 December 2026; 2.0e8, 5.3e8 and 1.1e9 a
#: radiation) 0.3 GHz 2 x 53 in 344 s (1.50 %) and 1 GHz 1 x 20 in 378 s (0.42 %); with the
#: fast sums' steps held to tol / sqrt(8) (1.8e8, 4.8e8 and 9.5e8) 0.3 GHz 2 x 59 in 302 s
#: (1.42 %); the budget stays
AUTO_BUDGET_PAIRS = 4.4e10
#: the fewest LSQR iterations in all "auto" runs Gauss-Newton with: on the paper's dish the
#: weak directions need tens of iterations (one step of 27 at 0.6 GHz takes the defect
#: correction's 2.21 % RRMS to 1.24 %, one of 31 to 0.76 %), so below this the defect
#: correction alone is kept
AUTO_MIN_LSQR = 20


@dataclass(frozen=True)
class Choice:
    """The refinement :func:`choose_method` picks: ``method`` (``defect`` or ``gauss-newton``),
    ``why`` (one line, the SurfaceMap's ``gn_choice``), and the ``steps`` and ``inner`` LSQR
    iterations per step "auto" affords within :data:`AUTO_BUDGET_PAIRS` (None: the options'
    own)."""

    method: str
    why: str
    steps: int | None = None
    inner: int | None = None

    def applied(self, options: GaussNewtonOptions | None) -> GaussNewtonOptions:
        """``options`` (None: the defaults) with this choice's steps and LSQR iterations; coarse
        steps, if asked for, still leave the last step on all cells."""
        options = options or GaussNewtonOptions()
        if self.steps is None or self.inner is None:
            return options
        return replace(options, iterations=self.steps, inner=self.inner,
                       coarse=min(options.coarse, self.steps - 1))


IN_PROCESS = ("gauss-newton computes its Jacobian in this process, not in blocks on Dask: drop "
              "--scheduler / --workers (the Dask runner), or refine with the defect correction")


def model_pairs(model: WaveForward, sphere, F: float, D: float) -> float:
    """The cost of one radiation of ``model`` on the scan's sphere, in direct pair evaluations:
    PO samples times field points for the direct sum, the plan's estimate for the fast one
    (:func:`raysim.optics.fast.radiator.estimated_cost`)."""
    from raysim.optics.fast.radiator import quadrature_cost
    from raysim.optics.po import C0, DEFAULT_SAMPLES_PER_WAVELENGTH
    from raysim.surface.quadrature import plan, targets_around

    spw = model.samples_per_wavelength or DEFAULT_SAMPLES_PER_WAVELENGTH
    points = sphere.points(F).reshape(-1, 3)
    wave = model.job(sphere, F, D, None).wave()  # the quadrature the model's own radiation uses
    quadrature = plan(model.paraboloid(D, F), C0 / model.frequency_hz, spw,
                      targets_around(points, (0.0, 0.0, F), wave.k_hat))
    return quadrature_cost(quadrature, points, model.wavenumber(),
                           (0.0, 0.0, F), getattr(model, "radiator", "direct"),
                           getattr(model, "radiator_tol", 1e-6))[0]


def has_exact_jacobian(model: object) -> bool:
    """Whether :class:`solver.jacobian.WaveJacobian` linearises ``model`` exactly: a
    :class:`WaveForward` whose scattered field is PO's (with PTD's rim), not a subclass with
    other physics (the go+edge model, :class:`solver.forward.GOEdgeForward`)."""
    return isinstance(model, WaveForward) and \
        type(model)._scattered is WaveForward._scattered


def choose_method(name: str, model: ForwardModel | None, scan, iterations: int,
                  options: GaussNewtonOptions | None = None) -> Choice:
    """The refinement for ``model`` (:class:`Choice`), before any work is done, so that a
    request that cannot run is one line.

    Gauss-Newton needs the PO or PO + PTD model (:func:`has_exact_jacobian`) computed in this
    process (not inside :func:`solver.forward.distributed`). ``auto`` takes it where at least
    :data:`AUTO_MIN_LSQR` LSQR iterations fit :data:`AUTO_BUDGET_PAIRS` pair evaluations (two
    radiations of the model per iteration, :func:`model_pairs`), and spends as many iterations
    as fit (up to the options' steps times their iterations, ``options``, default
    :class:`GaussNewtonOptions`) in as few steps of up to the options' iterations as they
    fill; else the defect correction alone.
    """
    if name not in REFINE_METHODS:
        raise SolverError(f"unknown refine method {name!r}: choose one of "
                          f"{', '.join(REFINE_METHODS)}")
    if iterations == 0 or name == "defect":
        return Choice("defect", "requested" if name == "defect" else "refine 0")
    refused = None
    if not has_exact_jacobian(model):
        named = getattr(model, "name", "none")
        refused = (f"gauss-newton needs the po or po+ptd model (its exact Jacobian); the "
                   f"refinement's model is {named!r}", f"auto: the {named} model")
    elif active_runner() is not None:
        refused = IN_PROCESS, "auto: the model's fields run on a Dask runner"
    if refused is not None:
        if name == "gauss-newton":
            raise SolverError(refused[0])
        return Choice("defect", refused[1])
    if name == "gauss-newton":
        return Choice("gauss-newton", "requested")
    opts = options or GaussNewtonOptions()
    pairs = max(model_pairs(model, scan.sphere, scan.F, scan.D), 1.0)  # 0 for a dish with no samples
    # LSQR iterations the budget affords in all, up to what the options ask for; spent in as
    # few steps of up to opts.inner as they fill: below ~1 GHz the deformation is a small
    # fraction of the wavelength, the model nearly linear, and each new step restarts LSQR's
    # Krylov space (0.3 GHz on the paper's dish: 2 x 46 reach 1.73 % RRMS, 3 x 30 1.91 %; 2 x 51 1.66 %)
    affordable = int(AUTO_BUDGET_PAIRS // (2.0 * pairs))
    total = min(affordable, opts.iterations * opts.inner)
    steps = max(1, min(opts.iterations, -(-total // opts.inner)))
    inner = total // steps
    budget = f"{pairs:.2g} pair evaluations per radiation, {AUTO_BUDGET_PAIRS:.2g} in all"
    fewest = min(AUTO_MIN_LSQR, opts.iterations * opts.inner)
    if total >= fewest:
        plural = "s" if steps > 1 else ""
        return Choice("gauss-newton", f"auto: {budget}: {steps} step{plural} of {inner} LSQR "
                                      "iterations", steps, inner)
    return Choice("defect", f"auto: {budget} leave {affordable} LSQR iterations, fewer than "
                            f"{fewest} (Gauss-Newton would take well over 10 minutes; "
                            "--refine-method gauss-newton asks for it)")


def report_attrs(report: GaussNewtonReport | None, why: str) -> dict:
    """SurfaceMap attributes of a Gauss-Newton run (``gn_*``), or of its absence."""
    if report is None:
        return {"gn_used": False, "gn_choice": why}
    return {
        "gn_used": True, "gn_choice": why, "gn_method": report.describe(),
        "gn_misfit_rms": ",".join(f"{v:.4e}" for v in report.misfit_rms),
        "gn_update_rms_m": ",".join(f"{v:.3e}" for v in report.update_rms),
        "gn_lsqr_iterations": ",".join(str(v) for v in report.inner_iterations) or "none",
        "gn_step_factor": ",".join(f"{v:g}" for v in report.step_factor) or "none",
        "gn_seconds": ",".join(f"{v:.1f}" for v in report.seconds) or "none",
        "gn_coarse_steps": int(sum(report.coarse)),
        "gn_noise_rms": report.noise_rms, "gn_stopped": report.stopped,
        "gn_regularisation": "LSQR stopped by the discrepancy principle (misfit^2 at the "
                             "noise's chi-square expectation + 2 sd); no penalty term",
        "gn_jvp_calls": report.jvp_calls, "gn_vjp_calls": report.vjp_calls,
        "gn_gain_factor": report.gain_factor,
    }
