"""The fast (multilevel) radiator: the direct sum's field, sampled per cluster of elements on a
chart of the target sphere and interpolated up a tree (see :mod:`raysim.optics.fast.radiator`)."""
