"""PO on a panelled dish: as the gaps close, the field tends to the gapless dish's.

The panels' quadrature has negative weights (the circular segments cut from a panel at its
concave ring edge) and samples beside a gap whose ray grazes the neighbouring panel's facet:
both must leave the PO integral that of the surface that is there. The missing strips are the
only difference, so the field's change is linear in the gap width.
"""

import numpy as np
import pytest

from raysim.maps.sphere import SphereGrid
from raysim.optics import po
from raysim.surface.mesh import paraboloid
from raysim.surface.panels import PanelLayout

D, F = 20.0, 8.0
LAYOUT = (0.0, 4.0, 7.0, 10.0), (6, 12, 18)


@pytest.fixture(scope="module")
def fields():
    wave = po.Illumination.plane_wave(1e9, (0, 0, -1), (1, 0, 0))
    grid = SphereGrid(3.0, 12, 16)
    smooth = po.sphere_field(paraboloid(D, F, 1.0), grid, wave).E
    gapped = {gap: po.sphere_field(paraboloid(D, F, 1.0, PanelLayout(*LAYOUT, gap)), grid, wave).E
              for gap in (1e-3, 1e-4)}
    return smooth, gapped


def test_panelled_field_tends_to_the_gapless_one_linearly_in_the_gap(fields):
    smooth, gapped = fields
    scale = np.abs(smooth).max()
    change = {gap: np.abs(E - smooth).max() / scale for gap, E in gapped.items()}
    # strips of width g over ~180 m of gaps on a 314 m^2 aperture: ~6e-4 of it per mm
    assert change[1e-4] < 3e-4
    assert 7.0 < change[1e-3] / change[1e-4] < 13.0


def test_every_sample_of_the_panels_is_lit_on_axis():
    dish = paraboloid(D, F, 1.0, PanelLayout(*LAYOUT, 1e-3))
    wave = po.Illumination.plane_wave(1e9, (0, 0, -1), (1, 0, 0))
    stats = po.ElementStats()
    for _ in po.po_elements(dish, wave, po.plan(dish, wave.wavelength, 1.5), stats=stats):
        pass
    assert stats.n_lit == stats.n_samples > 1000
