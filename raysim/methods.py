"""The simulation methods, named once: what ``--method`` accepts, what a scene's ``method`` key
and a dataset spec's take, and (with ``measured``) what a FieldMap's ``method`` attribute says.

The engines themselves live in :mod:`raysim.optics` (which re-exports :data:`METHODS`);
adding an engine is one entry here and its branch in :func:`raysim.simulate.simulate`.
A leaf module, so that every layer (the FieldMap contract at the bottom included) can read it.
"""

METHODS: tuple[str, ...] = ("go", "po", "po+ptd", "go+edge")
"""Simulation methods: geometric optics, physical optics, PO plus the edges' fringe field, and
the high-frequency wave engine (the geometric wave of the ray tubes plus edge diffraction)."""

WAVE_METHODS: tuple[str, ...] = ("po", "po+ptd", "go+edge")
"""The methods that give intensities at the cell centres (``sampling = centre``)."""

MEASURED = "measured"
"""The ``method`` of a FieldMap measured by the scanning rig."""

FIELDMAP_METHODS: tuple[str, ...] = (*METHODS, MEASURED)
"""Every value a FieldMap's ``method`` attribute may take."""

__all__ = ["FIELDMAP_METHODS", "MEASURED", "METHODS", "WAVE_METHODS"]
