"""The per-process sample engine: what it keeps between samples changes no number.

The store's samples (made by a worker that reuses one GO tracer with its BVH refitted, and
the deformations' factors at the mesh vertices) are compared with the path of before: a
fresh mesh displaced by the plain deformation and traced with a BVH built for it alone.
"""

from __future__ import annotations

import numpy as np
import pytest

from raysim.dataset import draw_sample, open_dataset, parse_spec
from raysim.dataset.memo import Memo, VertexFactors, value_and_gradient
from raysim.optics import go
from raysim.simulate import go_subdivisions
from raysim.surface.mesh import paraboloid
from tests.raysim.dataset.conftest import ROOT, small_demo_text


@pytest.mark.slow  # reads a store made by a local Dask cluster
def test_stored_samples_equal_fresh_traces_bit_for_bit(measured_store, monkeypatch):
    monkeypatch.setenv("RAYSIM_THREADS", "1")  # as in the worker
    spec, path = measured_store
    ds = open_dataset(path)
    scene, dish = spec.scene, spec.scene.dish
    fresh_ideal = paraboloid(dish.diameter, dish.focal_length, dish.resolution, scene.panels)
    m = go_subdivisions(scene, fresh_ideal)[0]
    ideal = go.trace(fresh_ideal, scene.sphere, scene.source.direction, m).intensity
    assert ds["intensity_ideal"].values[0].tobytes() == ideal.tobytes()
    for i in range(spec.samples):
        draw = draw_sample(spec, i)
        fresh = paraboloid(dish.diameter, dish.focal_length, dish.resolution, scene.panels)
        expected = go.trace(fresh.deformed(draw.deformation), scene.sphere, scene.source.direction,
                            m).intensity
        assert ds["intensity"].values[i].tobytes() == expected.tobytes()


def test_measurement_effects_leave_the_clean_draws_as_they_were():
    plain = parse_spec(small_demo_text(measurement=False), base=ROOT / "scenes")
    measured = parse_spec(small_demo_text(), base=ROOT / "scenes")
    for i in range(plain.samples):
        a, b = draw_sample(plain, i), draw_sample(measured, i)
        assert a.effects is None and b.effects is not None
        assert a.params.keys() < b.params.keys()
        for key, value in a.params.items():
            assert np.array_equal(value, b.params[key], equal_nan=True)
        assert plain.grid.evaluate(a.deformation).tobytes() == measured.grid.evaluate(b.deformation).tobytes()


@pytest.mark.parametrize("budget", [1 << 30, 0])
def test_vertex_factors_give_each_deformation_bit_for_bit(budget):
    spec = parse_spec(small_demo_text(samples=4), base=ROOT / "scenes")
    ideal = paraboloid(spec.scene.D, spec.scene.F, spec.scene.dish.resolution, spec.scene.panels)
    x, y, panel = ideal.vertices[:, 0], ideal.vertices[:, 1], ideal.vertex_panel
    factors = VertexFactors(x, y, budget)
    for i in range(spec.samples):  # the factors of the first sample serve the others
        deformation = draw_sample(spec, i).deformation  # zernike, bumps, panels, rim astigmatism
        value, (gx, gy) = value_and_gradient(deformation, x, y, panel, factors)
        assert value.tobytes() == deformation(x, y, panel).tobytes()
        px, py = deformation.gradient(x, y, panel)
        assert gx.tobytes() == px.tobytes() and gy.tobytes() == py.tobytes()
    assert (factors.nbytes > 0) == (budget > 0)
    # a Memo with the factors answers the mesh's questions from one evaluation
    memo = Memo(deformation, factors)
    assert memo(x, y, panel).tobytes() == deformation(x, y, panel).tobytes()
    assert memo.gradient(x, y, panel)[0].tobytes() == px.tobytes()


def test_a_memo_keeps_panel_ids_apart_only_where_they_matter():
    spec = parse_spec(small_demo_text(samples=4), base=ROOT / "scenes")
    deformation = draw_sample(spec, 1).deformation  # with panel pistons and tilts
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-50.0, 50.0, 200), rng.uniform(-50.0, 50.0, 200)
    memo = Memo(deformation)
    with_ids = memo(x, y, np.zeros(200, dtype=np.int64))  # every point said to be on panel 0
    found = memo(x, y, None)  # panels found from (x, y)
    assert np.array_equal(found, deformation(x, y)) and not np.array_equal(found, with_ids)


@pytest.mark.slow  # go+edge of a 110 m dish at 0.3 GHz, twice
def test_go_edge_samples_are_what_simulate_gives():
    """A spec with method go+edge gets the go+edge engine (it once fell through to PO): the
    deformed intensity equals raysim.simulate's go+edge run of the same reflector to round-off,
    where PO's differ by the engines' gap (a few per cent at 0.3 GHz on this 1 m mesh)."""
    from raysim.dataset import engine
    from raysim.simulate import ENGINES, Options

    text = small_demo_text(measurement=False).replace('method = "go"', 'method = "go+edge"')
    spec = parse_spec(text, base=ROOT / "scenes")
    assert spec.method == "go+edge"
    deformation = draw_sample(spec, 0).deformation
    values = engine.intensity(spec, deformation, 0)
    ideal = engine.spec_reflector(spec)
    scene = spec.scene.with_overrides(frequency_hz=spec.frequencies[0])
    run = ENGINES["go+edge"](scene, ideal, ideal.deformed(deformation), Options(), "cpu",
                             lambda stage, fraction: None)
    lit = run.intensity > 1e-3 * run.intensity.max()
    assert np.allclose(values[lit], run.intensity[lit], rtol=1e-6)


def test_an_unknown_wave_method_is_refused():
    from raysim.dataset import engine

    spec = parse_spec(small_demo_text(measurement=False), base=ROOT / "scenes")
    with pytest.raises(ValueError, match="no wave engine"):
        engine.wave_intensity(spec.scene, engine.spec_reflector(spec), "ray")
