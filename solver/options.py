"""The inversion's options checked in one place, before any data is read or simulated.

:func:`check_options` is what ``raysim invert``, ``raysim report`` and :func:`solver.invert.invert`
call first, so a bad option is one line (:class:`~solver.errors.SolverError`) before any work,
and the bounds are the same wherever the options come from.
"""

from __future__ import annotations

import numbers
import re
from collections.abc import Sequence
from dataclasses import dataclass, field

from raysim.optics.fast.radiator import RADIATORS, tol_problem
from solver import boundary
from solver.aperture import MIN_N
from solver.equation import GAIN_MODES
from solver.errors import SolverError
from solver.fit import parse_terms
from solver.forward import MODELS, Forward, ForwardModel
from solver.gauss_newton import IN_PROCESS, REFINE_METHODS, GaussNewtonOptions
from solver.poisson import SOLVERS

MAX_N = 4096  # aperture grid points across D: 16.8 million unknowns, about 2 GB per solve
MAX_REFINE = 50
MAX_ITERATIONS = 1_000_000
MAX_UNCERTAINTY_SAMPLES = 10_000  # each draw is one more linear solve
DEFAULT_SOLVER = "multigrid"
DEFAULT_N = 256
DEFAULT_REFINE = 3
WEIGHTS = ("auto", "amplitude", "none")


#: the largest harmonic order a caller may allow the rim targets' fit (each order needs two
#: more targets, spread round the rim: 200 such points are more than any survey holds)
MAX_HARMONICS_CAP = 100


def _integer(name: str, value: object, lo: int, hi: int) -> None:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not lo <= value <= hi:
        raise SolverError(f"{name} must be an integer in {lo}..{hi}, got {value!r}")


def _real_in(name: str, value: object, lo: float, hi: float) -> None:
    """Refuse anything but a real number strictly between ``lo`` and ``hi``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not lo < value < hi:
        raise SolverError(f"{name} must be a number strictly between {lo:g} and {hi:g}, got {value!r}")


def check_options(*, solver: str | None = None, N: int | None = None, refine: int | None = None,
                  gain: str | None = None, iterations: int | None = None,
                  remove: str | Sequence[str] | None = None, model: str | None = None,
                  refine_method: str | None = None, blocks: bool = False, radiator: str | None = None,
                  radiator_tol: float | None = None) -> None:
    """Refuse inversion options outside their choices or bounds (None: not given).

    ``blocks``: the wave model's fields are to run in blocks on Dask (--scheduler, --workers),
    which Gauss-Newton's Jacobian does not (it runs in this process).
    """
    if solver is not None and solver not in SOLVERS:
        raise SolverError(f"unknown solver {solver!r}: choose one of {', '.join(SOLVERS)}")
    if N is not None:
        _integer("the grid (points across the diameter, --grid)", N, MIN_N, MAX_N)
    if refine is not None:
        _integer("the refinement iterations (--refine)", refine, 0, MAX_REFINE)
    if iterations is not None:
        _integer("the solver iterations (--iterations)", iterations, 1, MAX_ITERATIONS)
    if gain is not None and gain not in GAIN_MODES:
        # "none", the former name of "known", is still taken but no longer offered
        offered = ", ".join(mode for mode in GAIN_MODES if mode != "none")
        raise SolverError(f"unknown gain mode {gain!r}: choose one of {offered}")
    if model is not None and model not in MODELS:
        raise SolverError(f"unknown model {model!r}: choose one of {', '.join(MODELS)}")
    if refine_method is not None and refine_method not in REFINE_METHODS:
        raise SolverError(f"unknown refine method {refine_method!r}: choose one of "
                          f"{', '.join(REFINE_METHODS)}")
    if radiator is not None and radiator not in RADIATORS:
        raise SolverError(f"unknown radiator {radiator!r}: choose one of {', '.join(RADIATORS)}")
    if radiator_tol is not None and (problem := tol_problem(radiator_tol, "--radiator-tol")) is not None:
        raise SolverError(problem)
    if refine_method == "gauss-newton" and blocks:
        raise SolverError(IN_PROCESS)
    parse_terms(remove)


@dataclass(frozen=True)
class InvertOptions:
    """Every setting of an inversion, checked on construction (see :func:`invert` for each).

    ``remove`` is kept as the tuple of term names it parses to (piston, tilt, focus).
    """

    solver: str = DEFAULT_SOLVER
    N: int = DEFAULT_N
    rim: boundary.RimTargets | None = None
    remove: str | Sequence[str] | None = None
    refine_iterations: int = DEFAULT_REFINE
    gain: str = "auto"
    iterations: int | None = None
    omega: float | None = None
    tol: float = 1e-10
    forward: ForwardModel | Forward | None = field(default=None, compare=False)
    device: str | None = "cpu"
    uncertainty_samples: int = 32
    seed: int = 0
    max_harmonics: int = boundary.MAX_HARMONICS
    model: str | None = None
    weights: str = "auto"
    refine_method: str = "defect"
    gauss_newton: GaussNewtonOptions | None = None
    radiator: str = "fast"
    radiator_tol: float = 1e-6

    def __post_init__(self) -> None:
        check_options(solver=self.solver, N=self.N, refine=self.refine_iterations, gain=self.gain,
                      iterations=self.iterations, remove=self.remove, model=self.model,
                      refine_method=self.refine_method, radiator=self.radiator,
                      radiator_tol=self.radiator_tol)
        if self.weights not in WEIGHTS:
            raise SolverError(f"unknown weights {self.weights!r}: choose one of {', '.join(WEIGHTS)}")
        if self.device is not None and not (isinstance(self.device, str)
                                            and re.fullmatch(r"cpu|cuda(:\d+)?", self.device)):
            # refused by the forward models' Warp launch, but accepted without a refinement
            raise SolverError(f"unknown device {self.device!r}: use cpu or cuda")
        # a tolerance <= 0 left multigrid all NaN, NaN or >= 1 stopped at the zero start, and
        # an SOR factor outside (0, 2) diverges or never moves
        _real_in("the solver's relative tolerance (tol)", self.tol, 0.0, 1.0)
        if self.omega is not None:
            _real_in("the SOR relaxation factor (omega)", self.omega, 0.0, 2.0)
        _integer("the uncertainty's Monte Carlo draws (uncertainty_samples)",
                 self.uncertainty_samples, 0, MAX_UNCERTAINTY_SAMPLES)
        # the rim targets' harmonic order cap: 2.5 raised a bare TypeError in the fit, 0 or -3
        # a RimTargetsError that blamed the targets' spacing
        _integer("the rim targets' highest harmonic order (max_harmonics)", self.max_harmonics,
                 1, MAX_HARMONICS_CAP)
        if isinstance(self.seed, bool) or not isinstance(self.seed, numbers.Integral) or self.seed < 0:
            raise SolverError(f"the random seed (seed) must be an integer >= 0, got {self.seed!r}")
        if self.rim is not None and self.solver == "fft":
            raise SolverError("the fft solver works on the enclosing square and cannot use rim "
                              "targets; choose direct, multigrid, sor or gauss-seidel")
        object.__setattr__(self, "remove", parse_terms(self.remove))

    @property
    def terms(self) -> tuple[str, ...]:
        """The terms to remove after the solve."""
        return tuple(self.remove or ())
