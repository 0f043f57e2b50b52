"""The reflector's surface: meshes, deformations, panels, and the samples the engines use.

Modules:

- ``deformation``: surface errors delta(x, y) in metres along +z, with their slopes (the
  paper's Eq. 8, Zernike terms, Gaussian bumps, rigid panel errors).
- ``gridded``: a deformation given on a regular grid, and the harmonic (Laplace) fill of
  missing grid cells that the gridded maps and the solver share.
- ``mapfile``: deformation maps from files (CSV ``x,y,dz``, NetCDF), read and checked.
- ``panels``: ring layouts of panels with gaps.
- ``mesh``: trimesh reflector meshes (ideal paraboloid, deformed twin on the same
  triangulation, panels with gaps, meshes loaded from files) and their smooth surfaces.
- ``quadrature``: Gauss points with vector areas over the faces, lifted onto the smooth
  surface (the PO surface integral).
- ``edges``: the free edges of a mesh (rim, holes, panel-gap edges) and their line quadrature.
- ``obstacles``: feed cabins, support legs and meshes in the beam, as specs and triangles.
"""
