"""Exceptions a user can cause. The CLI turns each into one line and exit status 2."""


class RaysimError(Exception):
    """Base class: bad input, not a bug. Its message is one line meant for the user."""


class SceneError(RaysimError, ValueError):
    """A scene file or scene value is invalid (unknown key, wrong unit, impossible geometry)."""


class MeshError(RaysimError, ValueError):
    """A reflector mesh cannot be read or is unusable (empty, not a dish, no ideal counterpart)."""


class FieldMapError(RaysimError, ValueError):
    """A FieldMap file breaks the data contract (missing variable, attribute or unit)."""


class ProbeError(RaysimError, ValueError):
    """A probe is not a probe (a pattern with q < 0, a table not increasing in angle)."""


class DeviceError(RaysimError, RuntimeError):
    """The requested compute device (for example ``cuda``) is not available."""


class InstrumentError(RaysimError, RuntimeError):
    """An instrument is unreachable, silent, not the expected model, reports an error in its
    queue, or a motion does not reach its target."""


class GridError(RaysimError, ValueError):
    """A grid cannot be built as asked (an aperture grid of fewer than 2 points, D <= 0)."""


class SurfaceMapError(RaysimError, ValueError):
    """A SurfaceMap file breaks the data contract (missing variable, attribute or unit)."""
