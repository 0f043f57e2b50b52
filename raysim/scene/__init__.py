"""Scenes: TOML files -> a validated :class:`Scene` (SI units inside, degrees only in the file).

Modules:

- ``schema``: key checks of TOML tables (unknown keys, types, units in the key names).
- ``deformations``: the ``[[deformation]]`` tables -> a :class:`~raysim.surface.deformation.Deformation`.
- ``scene``: the scene itself (dish, panels, source, sphere, method) and :func:`load_scene`.
"""

from raysim.scene.scene import Dish, Scene, Source, load_scene, parse_scene

__all__ = ["Dish", "Scene", "Source", "load_scene", "parse_scene"]
