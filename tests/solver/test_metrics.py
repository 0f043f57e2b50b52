"""The paper's RMS / RRMS conventions, checked against the paper's own figures."""

import numpy as np

from solver import metrics
from solver.aperture import ApertureGrid
from tests.reference_go import paper_delta


def test_paper_deformation_rms_and_peak_to_peak_match_the_paper():
    """PAPER.tex Table 3: RMS 327.65 um, M = 1.2 mm for Eq. 8 on N = 256 (aperture points)."""
    grid = ApertureGrid(110.0, 256)
    X, Y = grid.XY
    delta = grid.masked(paper_delta(X, Y))
    assert abs(metrics.rms(grid, delta) - 327.65e-6) < 0.5e-6
    assert abs(metrics.peak_to_peak(grid, delta) - 1.2e-3) < 0.02e-3
    # a third of the deformation: the paper's 109.22 um case
    assert abs(metrics.rms(grid, delta / 3) - 109.22e-6) < 0.2e-6


def test_rrms_is_rms_of_the_difference_over_peak_to_peak():
    grid = ApertureGrid(2.0, 32)
    truth = grid.masked(grid.XY[0])             # x: peak-to-peak close to 2
    recovered = truth + 0.01
    assert np.isclose(metrics.rms_error(grid, recovered, truth), 0.01)
    assert np.isclose(metrics.rrms(grid, recovered, truth),
                      0.01 / np.ptp(grid.XY[0][grid.mask]))
