"""The optics engines: a plane wave on a reflector mesh -> field or intensity on the sphere.

Modules:

- ``runtime``: Warp set-up shared by every engine (kernel cache, device choice, launches
  split across the CPU's threads).
- ``go``: geometric-optics ray tubes -> cell-mean intensity (and the GO forward model).
- ``blockage``: obstacles in the beam: which rays they block, which sphere cells they hide.
- ``goprobe``: each ray tube's weight for a probe (its reflected polarisation and arrival
  angle as the probe reads them).
- ``po``: physical-optics surface currents radiated in float64 through the full dyadic
  Green's function; the ``Radiator`` every current-based engine shares.
- ``ptd``: Michaeli's fringe equivalent edge currents on the free edges, added to PO.
- ``sources``: a reflector's PO (and fringe) elements made once and radiated onto any block of
  field points, bit for bit the sums of the whole (what blocks of sphere points run).
- ``kernels/``: the Warp kernels of these engines, one module per engine.
"""

from raysim.methods import METHODS, WAVE_METHODS

__all__ = ["METHODS", "WAVE_METHODS"]
