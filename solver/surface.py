"""SurfaceMap, the solver's output: the contract now lives in :mod:`raysim.maps.surfacemap`.

Re-exported here under the names the solver's users know (``solver.surface.save``, ``load``,
``surfacemap``, ``validate``, ``grid_of``).
"""

from raysim.maps.surfacemap import (
    LONG_NAMES,
    OPTIONAL_VARS,
    REQUIRED_ATTRS,
    canonical,
    grid_of,
    load,
    save,
    surfacemap,
    validate,
)

__all__ = ["LONG_NAMES", "OPTIONAL_VARS", "REQUIRED_ATTRS", "canonical", "grid_of", "load", "save",
           "surfacemap", "validate"]
