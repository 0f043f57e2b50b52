"""The fast (multilevel) radiator: the direct sum's field, sampled per cluster of elements on a
chart of the target sphere and interpolated up a tree (see :mod:`raysim.optics.fast.radiator`)."""

#: the fast radiator's default tolerance: its fields agree with the direct sum to about this
#: relative RMS (here, outside :mod:`raysim.optics.fast.radiator`, so that the command line's
#: defaults and help texts read it without loading the radiator)
DEFAULT_TOL = 1e-6

__all__ = ["DEFAULT_TOL"]
