"""The inversion's options checked in one place, before any data is read or simulated.

:func:`check_options` is what ``raysim invert``, ``raysim report`` and :func:`solver.invert.invert`
call first, so a bad option is one line (:class:`~solver.errors.SolverError`) before any work,
and the bounds are the same wherever the options come from.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence

from solver.aperture import MIN_N
from solver.equation import GAIN_MODES
from solver.errors import SolverError
from solver.fit import parse_terms
from solver.forward import MODELS
from solver.gauss_newton import IN_PROCESS, REFINE_METHODS
from solver.poisson import SOLVERS

MAX_N = 4096  # aperture grid points across D: 16.8 million unknowns, about 2 GB per solve
MAX_REFINE = 50
MAX_ITERATIONS = 1_000_000


def _integer(name: str, value: object, lo: int, hi: int) -> None:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not lo <= value <= hi:
        raise SolverError(f"{name} must be an integer in {lo}..{hi}, got {value!r}")


def check_options(*, solver: str | None = None, N: int | None = None, refine: int | None = None,
                  gain: str | None = None, iterations: int | None = None,
                  remove: str | Sequence[str] | None = None, model: str | None = None,
                  refine_method: str | None = None, blocks: bool = False) -> None:
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
        raise SolverError(f"unknown gain mode {gain!r}: choose one of {', '.join(GAIN_MODES)}")
    if model is not None and model not in MODELS:
        raise SolverError(f"unknown model {model!r}: choose one of {', '.join(MODELS)}")
    if refine_method is not None and refine_method not in REFINE_METHODS:
        raise SolverError(f"unknown refine method {refine_method!r}: choose one of "
                          f"{', '.join(REFINE_METHODS)}")
    if refine_method == "gauss-newton" and blocks:
        raise SolverError(IN_PROCESS)
    parse_terms(remove)
