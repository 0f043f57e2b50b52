"""Intensity between the cell centres of a FieldMap (the simulated rig's field): kept in
:mod:`raysim.maps.interp`, where the dataset's measurement effects use it too."""

from raysim.maps.interp import FieldSampler, SphereField

__all__ = ["FieldSampler", "SphereField"]
