"""raysim: reflector surface deformation from one intensity scan on a hemisphere at the focus.

Subpackages, from the ground up (a layer imports only from layers below it; the contracts in
``pyproject.toml`` enforce it):

- ``maps``: the probe sphere's grid and the FieldMap contract (NetCDF).
- ``surface``: reflector meshes, deformations delta(x, y) (m along +z), panels, quadrature, edges.
- ``scene``: TOML scenes -> a validated :class:`~raysim.scene.Scene` (SI units inside).
- ``optics``: the engines on Warp: GO ray tubes, PO currents, PTD edge currents.
- ``simulate``: scene -> FieldMap, both reflectors through one engine.
- ``dataset``: bulk training data on Dask into Zarr (beside ``solver``, a top-level package).
- ``render``: pictures only, headless.
- ``pipeline``: end-to-end runs (``report``, ``paper``).
- ``cli``: the ``raysim`` command; ``console`` its entry point (signal handlers first).

Leaves any layer may use: ``errors`` (user errors), ``version``, ``methods`` (the simulation
methods, named once), ``files`` (the shipped examples, output guards), ``tomlschema`` (the one
TOML checker).
"""

from raysim.version import __version__

__all__ = ["__version__", "load_fieldmap", "load_scene", "save_fieldmap", "simulate"]


def __getattr__(name: str):
    # the public API, imported on first use so that `import raysim` stays light
    if name == "load_scene":
        from raysim.scene import load_scene

        return load_scene
    if name == "simulate":
        from raysim.simulate import simulate

        return simulate
    if name in ("save_fieldmap", "load_fieldmap"):
        from raysim.maps import fieldmap

        return fieldmap.save if name == "save_fieldmap" else fieldmap.load
    raise AttributeError(f"module 'raysim' has no attribute {name!r}")
