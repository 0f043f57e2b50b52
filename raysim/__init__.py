"""raysim: reflector surface deformation from one intensity scan on a hemisphere at the focus.

Modules, in the order data flows through them (a module imports only from earlier ones):

- ``scene``: TOML scenes -> validated :class:`~raysim.scene.Scene` (SI units inside).
- ``deformation``: surface errors delta(x, y) (m along z) with their slopes.
- ``geometry``: trimesh reflector meshes (ideal, deformed, panels with gaps, loaded files).
- ``sphere``: the probe hemisphere's (theta, phi) grid and the ideal GO relations.
- ``go``: geometric-optics ray tubes with Warp -> intensity on the sphere.
- ``field``: the FieldMap NetCDF contract.
- ``render``: pictures; ``dataset``: bulk data on Dask; ``cli``: the ``raysim`` command.
"""

__version__ = "0.1.0"
