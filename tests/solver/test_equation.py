"""FA, G, the power gain and the noise bias of the deformation-intensity equation."""

import numpy as np

from solver.equation import G, debias, intensity_ratio_fa, noise_variance, power_gain

F, D, R = 33.0, 110.0, 10.0


def test_G_follows_the_path_from_reflector_to_sphere():
    assert G(0.0, F, R) == -2 * F * (F - R) / R
    # at the rim z = D^2 / 16F and d = F + z - R
    assert np.isclose(G(D / 2, F, R), -2 * F * (F + D**2 / (16 * F) - R) / R)


def test_fa_is_the_intensity_ratio_minus_one_and_nan_where_unlit():
    fa = intensity_ratio_fa([2.0, 1.0, 0.0, np.nan], [2.2, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(fa[:2], [0.1, 0.0])
    assert np.all(np.isnan(fa[2:]))


def test_power_gain_recovers_any_constant_scale(paper_field, sphere):
    area = sphere.cell_area()
    i, i0 = paper_field["intensity"].values, paper_field["intensity_ideal"].values
    assert abs(power_gain(i, i0, area) - 1) < 1e-9      # GO conserves power exactly
    for c in (0.37, 1.0, 5.2):
        assert np.isclose(power_gain(c * i, i0, area), c, rtol=1e-9)


def test_noise_variance_is_recovered_from_the_data(paper_field):
    i, i0 = paper_field["intensity"].values, paper_field["intensity_ideal"].values
    v = 2.3e-3**2
    noisy = i * (1 + np.sqrt(v) * np.random.default_rng(5).standard_normal(i.shape))
    assert np.isclose(noise_variance(intensity_ratio_fa(noisy, i0), 79), v, rtol=0.05)
    assert noise_variance(intensity_ratio_fa(i, i0), 79) < 1e-3 * v


def test_debias_removes_the_reciprocal_bias():
    """Noisy intensities of a power-conserving FA pattern: the gain-corrected FA is biased by
    about the noise variance v; after debias its mean is the true mean."""
    rng = np.random.default_rng(7)
    v = 0.01**2
    ratio = 1 + 4e-3 * np.where(np.arange(400_000) % 2 == 0, 1.0, -1.0)   # I / I_ideal, mean 1
    fa_true = 1 / ratio - 1
    i0 = np.ones(ratio.size)
    i = ratio * (1 + np.sqrt(v) * rng.standard_normal(ratio.size))
    fa = intensity_ratio_fa(i / power_gain(i, i0, 1.0), i0)
    assert abs(np.mean(fa) - np.mean(fa_true) - v) < 0.2 * v
    assert abs(np.mean(debias(fa, v)) - np.mean(fa_true)) < 0.2 * v
