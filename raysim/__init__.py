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
        from raysim import field

        return field.save if name == "save_fieldmap" else field.load
    raise AttributeError(f"module 'raysim' has no attribute {name!r}")
