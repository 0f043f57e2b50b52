"""Data on the probe sphere and its contracts, the ground every other layer stands on.

Modules:

- ``sphere``: the probe hemisphere's (theta, phi) cell grid about the focus, and the ideal
  GO relations between the aperture and the sphere (r = 2F tan(theta/2), I/I0 = (rho/R)^2).
- ``fieldmap``: the FieldMap contract (``xarray.Dataset``: intensity on (theta, phi) cells,
  with the attributes every reader works from), its checks, saving and loading.
- ``netcdf``: atomic NetCDF writing and reading shared by the contracts.
"""
