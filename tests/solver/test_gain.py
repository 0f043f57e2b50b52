"""An unknown gain: the shape delta_c a scale error makes, its removal, and the gain estimate.

The data are exact GO from the independent reference trace (tests/reference_go.py). The shape
of delta_c is checked against a one-dimensional radial integral of G Laplacian(delta_c) = 1
(the linear answer) and against the pipeline's own response to a scale error of 1e-4 (the
model-based answer), so the removal takes out what a wrong gain puts in and nothing else.
"""

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from raysim.maps.sphere import SphereGrid, theta_rim
from solver import metrics
from solver.aperture import ApertureGrid
from solver.equation import G
from solver.gainmode import estimate_gain, resolve_gain
from solver.invert import delta_c_mode, invert
from solver.linear import LinearInverse, Scan
from solver.unobservable import unobservable
from tests.reference_go import cell_mean_intensity, go_fieldmap, paper_delta
from tests.solver.conftest import D, F, R

EPS = 1e-4  # a scale error small enough for the map's response to stay linear


def scaled(field, c):
    out = field.copy(deep=True)
    out["intensity"] = out["intensity"] * c
    return out


def radial_delta_c(r, a):
    """G Laplacian(delta) = 1 on the disk, delta(a) = 0, by quadrature of the radial ODE:
    (r delta')' = r / G(r), so delta'(r) = (1/r) int_0^r s / G(s) ds."""
    s = np.linspace(0.0, a, 20001)
    inner = cumulative_trapezoid(s / G(s, F, R), s, initial=0.0)
    slope = np.divide(inner, s, out=np.zeros_like(s), where=s > 0)
    delta = cumulative_trapezoid(slope, s, initial=0.0)
    return np.interp(r, s, delta - delta[-1])


def test_auto_gain_is_known_for_simulations_and_estimated_for_scans():
    assert not resolve_gain("auto", "go").estimated
    assert not resolve_gain("auto", "po+ptd").estimated
    assert resolve_gain("auto", "measured").estimated
    assert resolve_gain("power", "go").estimated
    assert not resolve_gain("known", "measured").estimated
    assert not resolve_gain("none", "measured").estimated


def test_the_linear_delta_c_solves_the_radial_equation(paper_field):
    grid = ApertureGrid(D, 256)
    mode = delta_c_mode(LinearInverse(Scan.from_fieldmap(paper_field), grid, "multigrid"),
                        refined=False)
    expected = radial_delta_c(grid.r, grid.a)
    inside = grid.mask & (grid.r < 0.97 * grid.a)  # the resampling's last band is extrapolated
    assert np.max(np.abs(mode[inside] - expected[inside])) < 0.01 * np.max(np.abs(expected))


@pytest.mark.parametrize("refine", [0, 2])
def test_a_scale_error_makes_the_delta_c_shape(paper_field, refine):
    """Data read 1e-4 high, gain trusted: the map moves by the FA offset times delta_c."""
    options = dict(gain="known", refine_iterations=refine, N=128, truth=None)
    exact = invert(paper_field, **options)["deformation"].values
    wrong = invert(scaled(paper_field, 1 + EPS), **options)["deformation"].values
    grid = ApertureGrid(D, 128)
    mode = delta_c_mode(LinearInverse(Scan.from_fieldmap(paper_field), grid, "multigrid"),
                        refined=refine > 0)
    moved = wrong - exact
    rest, coef = unobservable(grid, {"delta_c": mode}).remove(grid, moved)
    b = coef["delta_c"]
    assert b == pytest.approx(1 / (1 + EPS) - 1, rel=0.01)
    assert metrics.rms(grid, rest) < 0.01 * metrics.rms(grid, moved)


@pytest.fixture(scope="module")
def cut_fields():
    """The paper's case scanned up to the rim image and no further (the rows of a scan that
    stops at the rim), deformed and ideal, with 2 % of the samples missing."""
    sphere = SphereGrid(R, 80, 360, theta_max=theta_rim(D, F))
    ideal = cell_mean_intensity(sphere, F, D)
    field = go_fieldmap(sphere, F, D, paper_delta, ideal=ideal)
    values = field["intensity"].values.copy()
    values[np.random.default_rng(5).random(values.shape) < 0.02] = np.nan
    return field.assign(intensity=(("theta", "phi"), values))


def test_an_estimated_gain_leaves_delta_c_out_and_the_rest_as_good(cut_fields):
    """Scale 1.03 injected, gain estimated: the estimate recovers it, the map without delta_c
    is within 2x of the known-gain map's error, and the removed coefficient is the truth's
    own delta_c content plus the estimate's residual FA offset."""
    injected = 1.03
    known = invert(cut_fields, gain="known", refine_iterations=2, N=128, truth=paper_delta)
    est = invert(scaled(cut_fields, injected), gain="power", refine_iterations=2, N=128,
                 truth=paper_delta)
    a = est.attrs
    assert not a["gain_known"] and not a["delta_c_observable"]
    assert abs(a["gain"] / injected - 1) < 2e-4
    assert est.attrs["rms_m"] < 2 * known.attrs["rms_m"]
    grid = ApertureGrid(D, 128)
    mode = delta_c_mode(LinearInverse(Scan.from_fieldmap(cut_fields), grid, "multigrid"),
                        refined=True)
    _, coef = unobservable(grid, {"delta_c": mode}).remove(grid, grid.masked(paper_delta(*grid.XY)))
    in_truth = coef["delta_c"]
    residual_offset = injected / a["gain"] - 1   # FA offset the estimate leaves in the data
    assert a["removed_delta_c"] - in_truth == pytest.approx(residual_offset, abs=2e-6)


def test_the_gain_estimate_states_its_own_spread(paper_field, sphere):
    """The stated std of the power-balance scale against its scatter over 24 noisy scans."""
    clean = paper_field["intensity"].values
    ideal = paper_field["intensity_ideal"].values
    rel = 0.01 * np.log(10) / 10               # 0.01 dB per reading
    rng = np.random.default_rng(3)
    scales, stds = [], []
    for _ in range(24):
        noisy = clean * (1 + rel * rng.standard_normal(clean.shape))
        g = estimate_gain(noisy, ideal, sphere, 79, rel**2)
        scales.append(g.scale)
        stds.append(g.std)
    assert np.std(scales, ddof=1) == pytest.approx(np.mean(stds), rel=0.35)


def test_one_reading_per_point_still_states_the_spread_of_the_noise(paper_field, sphere):
    """A scan of one reading per point has intensity_std NaN everywhere (no spread from one
    reading): the stated std comes from the noise v, as without intensity_std, never 0."""
    clean = paper_field["intensity"].values
    ideal = paper_field["intensity_ideal"].values
    rel = 0.01 * np.log(10) / 10
    rng = np.random.default_rng(4)
    unstated = np.full_like(clean, np.nan)
    scales, stds = [], []
    for _ in range(24):
        noisy = clean * (1 + rel * rng.standard_normal(clean.shape))
        g = estimate_gain(noisy, ideal, sphere, 79, rel**2, unstated)
        scales.append(g.scale)
        stds.append(g.std)
    assert min(stds) > 0
    assert np.std(scales, ddof=1) == pytest.approx(np.mean(stds), rel=0.35)
    assert np.isnan(estimate_gain(noisy, ideal, sphere, 79, np.nan, unstated).std)  # noise unknown: none


@pytest.mark.parametrize("c", [3.7e-9, 0.4, 2.6])
def test_a_trusted_gain_on_another_scale_is_refused_and_an_estimated_one_inverts_it(paper_field, c):
    """Readings in W (3.7e-9 of the ideal's scale) with the gain trusted gave a map of 3e8 m
    RMS and no word: the trusted scale is refused beyond a power balance of 1/2 .. 2, the
    estimated one recovers the scale and the map."""
    from solver.errors import SolverError

    with pytest.raises(SolverError, match=f"holds {c:.3g} times the ideal's total power"):
        invert(scaled(paper_field, c), gain="known", N=64, refine_iterations=0)
    est = invert(scaled(paper_field, c), gain="power", N=64, refine_iterations=0, truth=paper_delta)
    same = invert(paper_field, gain="power", N=64, refine_iterations=0, truth=paper_delta)
    assert est.attrs["gain"] == pytest.approx(c * same.attrs["gain"], rel=1e-9)
    assert est.attrs["rms_m"] == pytest.approx(same.attrs["rms_m"], rel=1e-6)
    if c < 1e-2:  # the scale as a number one can read (it printed "0.000000" in W)
        from solver.run import summary

        assert f"scale {est.attrs['gain']:.6g} +-" in "\n".join(summary(est))


def test_a_trusted_gain_within_the_balance_is_taken_as_it_is(paper_field):
    """A scale of 1.5 is an error a trusted gain leaves in the map, not refused: the map's RMS
    against the truth grows by the delta_c it puts in."""
    good = invert(paper_field, gain="known", N=64, refine_iterations=0, truth=paper_delta)
    off = invert(scaled(paper_field, 1.5), gain="known", N=64, refine_iterations=0, truth=paper_delta)
    assert off.attrs["gain"] == 1.0 and off.attrs["rms_m"] > 10 * good.attrs["rms_m"]
