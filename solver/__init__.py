"""solver: intensity scan (FieldMap) -> surface map (SurfaceMap) of the main reflector.

Frame and units as docs/physics.md: sphere angles theta, phi in rad; aperture x, y and delta in m.
Modules, in the order the data flow through them:

- ``errors``: the solver's user errors (SolverError, RimTargetsError, SurfaceMapError), all
  :class:`raysim.errors.RaysimError`, so the CLI prints one line and exits 2.
- ``aperture``: the aperture grid (:mod:`raysim.maps.aperture`, re-exported) and the smallest
  N the solvers accept.
- ``equation``: FA = I_ideal / I_def - 1, G = -2 F d / R, the power gain, the noise bias.
- ``resample``: sphere (theta, phi) -> aperture (x, y) through r = 2F tan(theta/2), with
  inpainting of missing samples (blocked cells along phi) and the continuation to the rim.
- ``poisson``: the Shortley-Weller Laplacian on the disk and the solvers direct, multigrid,
  gauss-seidel, sor (on that matrix) and fft (the paper's square comparison).
- ``boundary``: rim values: zero (the paper) or a harmonic fit to rim targets (CSV x,y,dz).
- ``linear``: the linear inversion (the scan a FieldMap gives, FA -> delta with one rim treatment).
- ``forward``: the refinement's forward models (GO, PO, PO+PTD), each owning its caches.
- ``wave``: how wave-optics intensity answers a deformation: weights, the wave preconditioner.
- ``nonlinear``: model-based refinement (defect correction with Anderson acceleration).
- ``refinement``: the choice of forward model and preconditioner.
- ``central``: the mode a blocked centre (a feed cabin's shadow) leaves unobservable.
- ``fit``: piston / tilt / focus removal and the per-panel adjustment table.
- ``metrics``: the paper's RMS and RRMS over the aperture's grid points.
- ``surface``: the SurfaceMap NetCDF contract (:mod:`raysim.maps.surfacemap`, re-exported).
- ``record``: what the SurfaceMap records of the inversion.
- ``invert``: the pipeline, :func:`invert` (FieldMap dataset -> SurfaceMap dataset) and its
  settings as one :class:`~solver.invert.InvertOptions`.
- ``run``: file in, file out (what ``raysim invert`` calls). The paper's tables, which run the
  engines and this package end to end, are in :mod:`raysim.pipeline.paper`.
"""

from solver.invert import invert
from solver.run import run_invert

__all__ = ["invert", "run_invert"]
