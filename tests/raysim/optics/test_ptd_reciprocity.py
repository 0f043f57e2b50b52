"""Reciprocity of the far field of a flat disk, and edges in a plate's shadow.

Reciprocity: for any scatterer, the far-field amplitude received with polarisation p2 in the
direction s when the wave travels along k with polarisation p1 equals the one received with p1
in the direction -k when the wave travels along -s with p2. Exact solutions obey it; PO does
not (its edge term is not reciprocal), while Keller's edge diffraction, which PO + PTD
reproduces on the Keller cone, is. So on a disk of radius 8 wavelengths, over random bistatic
geometries and polarisations, PO + PTD should be far closer to reciprocal than PO alone.
"""

from __future__ import annotations

import numpy as np
import pytest

from raysim.optics import po, ptd
from raysim.surface.edges import edge_quadrature
from raysim.surface.mesh import Reflector
from raysim.surface.quadrature import FaceQuadrature
from tests.flat import flat_disk

LAMBDA = 1.0
FAR = 2.0e4  # m, beyond 2 D^2 / lambda = 512 m


def far_amplitudes(disk, k_hat, e_hat, s_hat):
    """R exp(jkR) E in direction s_hat: PO and the rim's fringe part."""
    wave = po.Illumination.plane_wave(po.C0 / LAMBDA, k_hat, e_hat)
    P = FAR * np.atleast_2d(s_hat)
    radiator = po.Radiator(P, wave.k)
    for src in po.po_elements(disk, wave, FaceQuadrature(disk, LAMBDA / 4.0)):
        radiator.add_packed(src)
    norm = FAR * np.exp(1j * wave.k * FAR)
    return radiator.field()[0] * norm, ptd.edge_field(disk, P, wave, "rim").E[0] * norm


def unit(theta, phi):
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def transverse(d):
    a = np.cross(d, [0.3, 0.5, 0.8])
    a /= np.linalg.norm(a)
    return a, np.cross(d, a)


@pytest.mark.slow
def test_po_ptd_is_far_closer_to_reciprocal_than_po():
    disk = flat_disk(8.0 * LAMBDA, 2.0)
    rng = np.random.default_rng(3)
    defect_po, defect_ptd = [], []
    for _ in range(8):
        k1 = -unit(np.radians(rng.uniform(10, 70)), rng.uniform(0, 2 * np.pi))  # from above
        side = 1.0 if rng.uniform() < 0.5 else -1.0  # observed above or below the disk
        s1 = side * unit(np.radians(rng.uniform(10, 80)), rng.uniform(0, 2 * np.pi))
        for p1 in transverse(k1):
            for p2 in transverse(s1):
                po_12, edge_12 = far_amplitudes(disk, k1, p1, s1)
                po_21, edge_21 = far_amplitudes(disk, -s1, p2, -k1)
                S12, S21 = p2 @ (po_12 + edge_12), p1 @ (po_21 + edge_21)
                scale = max(abs(S12), abs(S21))
                defect_po.append(abs(p2 @ po_12 - p1 @ po_21) / scale)
                defect_ptd.append(abs(S12 - S21) / scale)
    rms_po, rms_ptd = np.sqrt(np.mean(np.square(defect_po))), np.sqrt(np.mean(np.square(defect_ptd)))
    assert rms_po > 0.2, rms_po  # PO is far from reciprocal here
    assert rms_ptd < rms_po / 4, (rms_ptd, rms_po)
    assert np.median(defect_ptd) < np.median(defect_po) / 5, (np.median(defect_ptd), np.median(defect_po))


def rectangle(x0, x1, y0, y1, z, n=6):
    X, Y = np.meshgrid(np.linspace(x0, x1, n), np.linspace(y0, y1, n), indexing="ij")
    v = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, z)])
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()
    return v, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def test_edges_in_a_shadow_carry_no_current():
    """A plate 2 m above another hides the half (y < 0) of the lower plate's edge x = 0 from
    a wave travelling down; the mesh has no smooth surface (edges and normals from facets)."""
    va, fa = rectangle(0.0, 6.0, -3.0, 3.0, 0.0)
    vb, fb = rectangle(-4.0, 2.0, -5.0, 0.0, 2.0)
    vertices = np.vstack([va, vb])
    faces = np.vstack([fa, fb + len(va)])
    normals = np.zeros_like(vertices)
    normals[:, 2] = 1.0
    plates = Reflector(vertices, faces, np.repeat([0, 1], [len(fa), len(fb)]), normals, 1.0, 12.0)
    edges = edge_quadrature(plates, 0.25, "all")
    wave = po.Illumination.plane_wave(po.C0 / LAMBDA, (0.0, 0.0, -1.0), (1.0, 0.0, 0.0))
    lit = ptd.lit_points(plates, edges, wave)
    p = edges.points
    lower_edge = (np.abs(p[:, 0]) < 1e-12) & (np.abs(p[:, 2]) < 1e-12)
    assert lower_edge.sum() > 20
    hidden = lower_edge & (p[:, 1] < -0.05)
    seen = lower_edge & (p[:, 1] > 0.05)
    assert not lit[hidden].any() and lit[seen].all()
    # elsewhere: the upper plate's edges and the lower plate's edges beyond the upper plate
    beyond = (p[:, 2] > 1.0) | (p[:, 0] > 2.05) | (p[:, 1] > 0.05)
    assert lit[beyond].all()
    elements = ptd.fringe_elements(edges, wave, lit)
    assert np.all(elements[15:23][:, hidden] == 0.0) and np.all(np.abs(elements[15:23][:, seen]).sum(axis=0) > 0)
