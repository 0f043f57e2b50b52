"""The go+edge forward model of the wave refinement (solver.forward.GOEdgeForward).

Against data from the PO + PTD engine (a different method: surface currents, not rays) on a
small dish of the paper's proportions at 1 GHz (D = 30 m, 100 wavelengths). The refinement
with this model on the paper's dish is benchmarks/bench_goedge.py --table3.
"""

import numpy as np
import pytest

from raysim.maps.sphere import SphereGrid
from raysim.optics import po, ptd
from raysim.surface.deformation import GaussianBumps
from raysim.surface.mesh import paraboloid
from solver.aperture import ApertureGrid
from solver.forward import GOEdgeForward, forward_for, model_for_method
from solver.nonlinear import extend_outside

D, F, R, FREQUENCY = 30.0, 9.0, 3.0, 1e9
TRUTH = GaussianBumps(((0.0, 0.0, 2e-4, 4.0), (5.0, -3.0, -1.5e-4, 2.5)))


def test_the_registry_knows_go_edge():
    assert model_for_method("go+edge") == "go+edge"
    model, text = forward_for("go+edge", {"frequency_hz": 3e9, "polarization": 0.0})
    assert isinstance(model, GOEdgeForward) and model.name == "go+edge" and "goedge" in text
    # models own their ideal fields: a go+edge model and a PO + PTD model never share one
    other = forward_for("po+ptd", {"frequency_hz": 3e9})[0]
    assert other.name == "po+ptd" and model._ideal is not other._ideal


@pytest.mark.slow
def test_go_edge_model_predicts_po_ptd_data():
    """The model's FA for the truth (as the refinement hands it over: gridded on the aperture)
    against PO + PTD data: within 10 % of FA's RMS, and four times closer than the GO model."""
    sphere = SphereGrid(R, 40, 12, 0.0, np.radians(76.0), 0.0, np.pi)
    wave = po.Illumination.plane_wave(FREQUENCY, (0, 0, -1), (1, 0, 0))
    dish = paraboloid(D, F, 3.0)
    I = [np.sum(np.abs(po.sphere_field(r, sphere, wave).E + ptd.sphere_edge_field(r, sphere, wave).E) ** 2,
                axis=-1) for r in (dish, dish.deformed(TRUTH))]
    fa_data = I[0] / I[1] - 1
    grid = ApertureGrid(D, 96)
    X, Y = grid.XY
    delta = extend_outside(grid, grid.masked(TRUTH(X, Y)))
    errors = {}
    for name in ("go+edge", "go"):
        model, _ = forward_for(name, {"frequency_hz": FREQUENCY})
        fa = model(sphere, F, D, grid.x, grid.y, None) / model(sphere, F, D, grid.x, grid.y, delta) - 1
        errors[name] = np.sqrt(np.mean((fa - fa_data) ** 2) / np.mean(fa_data**2))
    assert errors["go+edge"] < 0.1 and errors["go+edge"] < errors["go"] / 4, errors
