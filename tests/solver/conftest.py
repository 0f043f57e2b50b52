"""Shared data for the solver tests: exact GO FieldMaps from the independent reference trace.

The paper's case (docs/physics.md): D = 110 m, F = 33 m, R = 10 m, 90 x 360 one-degree cells. Each
map is traced once per session (a few seconds each).
"""

import numpy as np
import pytest

from raysim.maps.sphere import SphereGrid
from tests.reference_go import cell_mean_intensity, go_fieldmap, paper_delta

F, D, R = 33.0, 110.0, 10.0
A = 0.5 * D


def harmonic_delta(x, y):
    """About 200 um of astigmatism plus coma, both largest on the rim (m)."""
    rho = np.hypot(x, y) / A
    phi = np.arctan2(y, x)
    return 200e-6 * rho**2 * np.cos(2 * phi) + 60e-6 * (3 * rho**3 - 2 * rho) * np.cos(phi)


@pytest.fixture(scope="session")
def sphere():
    return SphereGrid(R, 90, 360)


@pytest.fixture(scope="session")
def ideal(sphere):
    return cell_mean_intensity(sphere, F, D)


@pytest.fixture(scope="session")
def paper_field(sphere, ideal):
    return go_fieldmap(sphere, F, D, paper_delta, ideal=ideal)


@pytest.fixture(scope="session")
def paper_field_third(sphere, ideal):
    return go_fieldmap(sphere, F, D, lambda x, y: paper_delta(x, y, scale=1 / 3), ideal=ideal)


@pytest.fixture(scope="session")
def harmonic_field(sphere, ideal):
    return go_fieldmap(sphere, F, D, harmonic_delta, ideal=ideal)
