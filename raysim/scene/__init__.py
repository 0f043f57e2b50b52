"""Scenes: TOML files -> a validated :class:`Scene` (SI units inside, degrees only in the file).

Modules:

- ``deformations``: the ``[[deformation]]`` tables -> a :class:`~raysim.surface.deformation.Deformation`.
- ``obstacles``: the ``[[obstacle]]`` tables -> obstacle specs (:mod:`raysim.surface.obstacles`).
- ``scene``: the scene itself (dish, panels, source, sphere, method), :func:`load_scene` and
  :func:`scene_of` (the scene a FieldMap records, re-parsed in one place).

The keys are checked by the one TOML checker, :mod:`raysim.tomlschema`.
"""

from raysim.scene.scene import Dish, Scene, Source, load_scene, parse_scene, scene_of

__all__ = ["Dish", "Scene", "Source", "load_scene", "parse_scene", "scene_of"]
