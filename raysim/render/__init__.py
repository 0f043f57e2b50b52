"""Pictures of FieldMaps and SurfaceMaps, headless: pyvista/VTK off-screen through EGL for 3D,
matplotlib (Agg) for maps and cuts, and the paper's figure set (the pictures of ``raysim report``,
which :mod:`raysim.pipeline.report` assembles).

Modules:

- ``backend``: EGL set-up for VTK (no X server, nothing for the user to set), off-screen
  plotters, exact-size matplotlib figures, PNG writing, ``--size`` parsing, RenderError.
- ``data``: reading either contract, the field quantities (FA, intensity, normalised
  intensity), colour limits, titles and RMS figures.
- ``field3d``: the probe hemisphere coloured by a quantity over the reflector (panels, gaps,
  focus, source direction), with an overview inset.
- ``surface3d``: the dish warped by delta (exaggeration stated), truth / recovered / error.
- ``charts``: (theta, phi) maps and cuts of a FieldMap; x-y maps and cuts of a SurfaceMap.
- ``api``: ``render(FILE, OUT.png, kind, size, quantity)``, what ``raysim render`` calls.
- ``figures``: the paper's Figs. 8-10 for one FieldMap and its SurfaceMap.

Only the pipeline layer and the CLI import this package; it may read every layer below.
"""

from raysim.render.api import KINDS, default_size, render, render_image
from raysim.render.backend import RenderError, parse_size
from raysim.render.data import FIELD_QUANTITIES, open_map

__all__ = ["FIELD_QUANTITIES", "KINDS", "RenderError", "default_size", "open_map", "parse_size", "render",
           "render_image"]
