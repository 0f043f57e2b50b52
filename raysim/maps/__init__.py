"""The grids and data contracts (sphere and aperture), the ground every other layer stands on.

Modules:

- ``sphere``: the probe hemisphere's (theta, phi) cell grid about the focus, and the ideal
  GO relations between the aperture and the sphere (r = 2F tan(theta/2), I/I0 = (rho/R)^2).
- ``fieldmap``: the FieldMap contract (``xarray.Dataset``: intensity on (theta, phi) cells,
  with the attributes every reader works from), its checks, saving and loading.
- ``aperture``: the N x N cell-centred aperture grid over [-D/2, D/2]^2 and its disk
  r < D/2, shared by the solver, the SurfaceMap, the datasets and the pictures.
- ``surfacemap``: the SurfaceMap contract (``xarray.Dataset``: delta on the aperture grid,
  with the inversion's assumptions in its attributes), its checks, saving and loading.
- ``netcdf``: atomic NetCDF writing and reading shared by the contracts.
- ``probe``: the probe on the sphere (polarisation, power pattern, what it reads of a field),
  its ``[probe]`` table and its FieldMap attributes.
"""
