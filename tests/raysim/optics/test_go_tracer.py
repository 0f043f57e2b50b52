"""The GO Tracer: one set-up traced for many twins of a mesh, each bit for bit as a fresh trace."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from raysim.errors import RaysimError
from raysim.maps.sphere import SphereGrid
from raysim.optics import go
from raysim.surface.deformation import GaussianBumps, PaperDeformation
from raysim.surface.mesh import Reflector, panel_footprint, paraboloid
from raysim.surface.panels import PanelLayout


def _same(a: go.GOResult, b: go.GOResult) -> bool:
    return (a.intensity.tobytes() == b.intensity.tobytes() and a.power_lit == b.power_lit
            and (a.n_shadowed, a.n_missed, a.n_rays) == (b.n_shadowed, b.n_missed, b.n_rays))


def _stacked_plates(z_upper: float) -> Reflector:
    """A plate of radius 8 m at z = 0 and one of radius 3.1 m at ``z_upper`` (facet hits)."""
    lower_xy, lower_faces = panel_footprint(PanelLayout((0.0, 8.0), (1,), 0.0), 0, 0.5)
    upper_xy, upper_faces = panel_footprint(PanelLayout((0.0, 3.1), (1,), 0.0), 0, 0.5)
    vertices = np.vstack([np.column_stack([lower_xy, np.zeros(len(lower_xy))]),
                          np.column_stack([upper_xy, np.full(len(upper_xy), z_upper)])])
    faces = np.vstack([lower_faces, upper_faces + len(lower_xy)])
    panel = np.concatenate([np.zeros(len(lower_faces), int), np.ones(len(upper_faces), int)])
    return Reflector(vertices, faces, panel, np.tile([0.0, 0.0, 1.0], (len(vertices), 1)), 20.0, 16.0)


@pytest.mark.parametrize("direction, subdivisions", [(go.ON_AXIS, 1), ((0.05, -0.02, -1.0), 2)])
def test_a_reused_tracer_equals_fresh_traces_of_every_twin(direction, subdivisions):
    ideal = paraboloid(40.0, 15.0, 1.5)
    grid = SphereGrid(5.0, 24, 60)
    twins = [ideal.deformed(PaperDeformation(40.0, 15.0, s)) for s in (1.0, -3.0)]
    twins.append(ideal.deformed(GaussianBumps(((3.0, -2.0, 4e-3, 2.5),))))
    tracer = go.Tracer(ideal, grid, direction, subdivisions)
    # twins in any order, the template between them: the refitted BVH follows each
    for reflector in [*twins, ideal, twins[0], *twins[::-1]]:
        fresh = go.trace(reflector, grid, direction, subdivisions)
        assert _same(tracer.trace(reflector), fresh)


def test_refitted_bvh_follows_moved_faces_into_and_out_of_shadow():
    grid = SphereGrid(10.0, 30, 36)
    above = _stacked_plates(2.0)
    upper = above.vertices[:, 2] > 1.0
    shifted = above.vertices.copy()
    shifted[upper, 0] += 4.0  # the upper plate over another part of the lower one
    lowered = above.vertices.copy()
    lowered[upper, 2] = -2.0  # the upper plate under the lower one
    twins = [dataclasses.replace(above, vertices=v) for v in (shifted, lowered)]
    tracer = go.Tracer(above, grid)
    first = tracer.trace(above)
    results = [tracer.trace(twin) for twin in twins]
    lower_xy = above.vertices[~upper, :2]
    hidden_before = np.hypot(*lower_xy.T) < 3.0
    hidden_after = np.hypot(lower_xy[:, 0] - 4.0, lower_xy[:, 1]) < 3.0
    # the faces' new places decide the shadow: new lower vertices hidden, old ones lit again
    assert first.n_shadowed >= hidden_before.sum() and results[0].n_shadowed >= hidden_after.sum()
    assert results[0].n_shadowed < hidden_before.sum() + hidden_after.sum()
    assert results[1].n_shadowed == int(upper.sum())  # under the lower plate: all hidden
    for twin, result in zip(twins, results, strict=True):
        assert _same(result, go.trace(twin, grid))
    assert _same(tracer.trace(above), first)


def test_a_tracer_refuses_a_mesh_of_other_faces():
    grid = SphereGrid(5.0, 12, 24)
    tracer = go.Tracer(paraboloid(40.0, 15.0, 2.0), grid)
    with pytest.raises(RaysimError, match="twins of its template"):
        tracer.trace(paraboloid(40.0, 15.0, 3.0))


def test_footprint_shortcut_changes_no_result():
    from raysim.surface.footprint import vertices_clear_of_other_faces
    from raysim.surface.panels import PanelLayout as Layout

    grid = SphereGrid(5.0, 24, 60)
    rings = ((0.0, 8.0, 14.0, 20.0), (6, 12, 18))
    gapped = paraboloid(40.0, 15.0, 1.5, Layout(*rings, 0.05))
    touching = paraboloid(40.0, 15.0, 1.5, Layout(*rings, 0.0))  # vertices on the next panel's edges
    plates = _stacked_plates(2.0)
    assert vertices_clear_of_other_faces(gapped.vertices, gapped.faces)
    assert not vertices_clear_of_other_faces(touching.vertices, touching.faces)
    assert not vertices_clear_of_other_faces(plates.vertices, plates.faces)
    for template in (gapped, touching):
        tracer = go.Tracer(template, grid, footprint_shortcut=True)
        for s in (1.0, -2.0):
            twin = template.deformed(PaperDeformation(40.0, 15.0, s))
            assert _same(tracer.trace(twin), go.trace(twin, grid))
        assert tracer._clear is (template is gapped)
    lowered = plates.vertices.copy()
    lowered[plates.vertices[:, 2] > 1.0, 2] = -2.0
    twin = dataclasses.replace(plates, vertices=lowered)
    tracer = go.Tracer(plates, grid, footprint_shortcut=True)
    result = tracer.trace(twin)
    assert result.n_shadowed > 0 and _same(result, go.trace(twin, grid))
