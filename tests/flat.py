"""The plane z = 0 as a reflector's smooth surface, for plates and disks in the PO and PTD tests."""

import numpy as np


class FlatSurface:
    """Height, slopes and normal (+z) of the plane z = 0, in the interface of a Reflector's surface."""

    def height(self, x, y, panel=None):
        return np.zeros(np.shape(x))

    def slope(self, x, y, panel=None):
        return np.zeros(np.shape(x)), np.zeros(np.shape(x))

    def normal(self, x, y, panel=None):
        n = np.zeros((*np.shape(x), 3))
        n[..., 2] = 1.0
        return n


def flat_disk(a: float, h: float):
    """A triangulated disk of radius a (m) in z = 0, triangles about h (m), normals +z."""
    import dataclasses

    from raysim.surface.mesh import paraboloid

    dish = paraboloid(2.0 * a, 1.0, h)  # only its aperture triangulation is used
    vertices = dish.vertices.copy()
    vertices[:, 2] = 0.0
    normals = np.zeros_like(vertices)
    normals[:, 2] = 1.0
    return dataclasses.replace(dish, vertices=vertices, vertex_normals=normals, surface=FlatSurface())
