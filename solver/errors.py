"""Errors a user of the solver can cause; each is a :class:`raysim.errors.RaysimError`.

The ``raysim`` command turns any of them into one line on stderr and exit status 2.
"""

from raysim.errors import RaysimError, SurfaceMapError


class SolverError(RaysimError, ValueError):
    """An inversion option is invalid (unknown solver name, grid too small, bad term name)."""


class RimTargetsError(RaysimError, ValueError):
    """A rim-target CSV (header ``x,y,dz``, metres) is unreadable, malformed or too sparse."""


__all__ = ["RimTargetsError", "SolverError", "SurfaceMapError"]
