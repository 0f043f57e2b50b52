"""Random surface errors of a dataset: laws, RMS targets, seeds, the rim astigmatism, Memo."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from raysim.dataset import draw_sample, load_spec, parse_spec, sample_seed, validation_mask
from raysim.dataset.memo import Memo
from raysim.dataset.models import RimAstigmatism
from raysim.dataset.zernike import ZernikeSeries
from tests.reference_zernike import radial, zernike_sum
from tests.surfaces import disk_rms

ROOT = Path(__file__).resolve().parents[3]
DEMO_TEXT = (ROOT / "scenes" / "dataset_demo.toml").read_text()


@pytest.fixture(scope="module")
def coarse_demo():
    """The demo spec with a 16 x 16 map, so hundreds of draws take seconds."""
    return parse_spec(DEMO_TEXT.replace("grid_n = 48", "grid_n = 16").replace("samples = 8", "samples = 300"),
                      base=ROOT / "scenes")


def test_rim_astigmatism_rms_and_slopes():
    a = 55.0
    d = RimAstigmatism(amplitude=2e-4, exponent=3.0, angle=0.3, radius=a)
    # RMS over the disk by polar quadrature, against |A| / sqrt(2 (p + 1))
    r = (np.arange(2000) + 0.5) / 2000 * a
    phi = (np.arange(720) + 0.5) / 720 * 2 * np.pi
    R, P = np.meshgrid(r, phi)
    values = d(R * np.cos(P), R * np.sin(P))
    rms = np.sqrt(np.sum(values**2 * R) / np.sum(R))
    assert rms == pytest.approx(2e-4 / np.sqrt(8.0), rel=1e-4)
    # value on the rim along the axis is A; slopes match central differences
    assert d(a * np.cos(0.3), a * np.sin(0.3)) == pytest.approx(2e-4)
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-50, 50, 200), rng.uniform(-50, 50, 200)
    h = 1e-4
    gx, gy = d.gradient(x, y)
    assert np.allclose(gx, (d(x + h, y) - d(x - h, y)) / (2 * h), rtol=1e-6, atol=1e-13)
    assert np.allclose(gy, (d(x, y + h) - d(x, y - h)) / (2 * h), rtol=1e-6, atol=1e-13)


def test_zernike_series_is_noll_normalised_orthogonal_and_has_exact_slopes():
    a = 55.0
    terms = [(n, m) for n in range(0, 7) for m in range(-n, n + 1, 2)]
    # polar Gauss-Legendre x uniform quadrature over the disk, exact for these polynomials
    nodes, weights = np.polynomial.legendre.leggauss(12)
    r = 0.5 * a * (nodes + 1.0)
    phi = (np.arange(32) + 0.5) / 32 * 2 * np.pi
    R, P = np.meshgrid(r, phi)
    w = np.meshgrid(weights * r, phi)[0] / np.sum(weights * r) / len(phi)
    X, Y = R * np.cos(P), R * np.sin(P)
    values = np.array([ZernikeSeries(((n, m, 1.0),), a)(X, Y) for n, m in terms])
    gram = np.einsum("ikl,jkl,kl->ij", values, values, w)
    assert np.allclose(gram, np.eye(len(terms)), atol=1e-12)  # RMS = coefficient, orthogonal
    # against the Jacobi-polynomial reference, one term and a whole random series
    n, m = 5, -3
    assert np.allclose(values[terms.index((n, m))], np.sqrt(2 * (n + 1)) * radial(n, m, R / a) * np.sin(3 * P))
    assert np.allclose(radial(5, 3, R / a), 5 * (R / a) ** 5 - 4 * (R / a) ** 3)  # the reference itself
    rng = np.random.default_rng(2)
    rows = tuple((n, m, rng.normal() * 1e-4) for n, m in terms)
    series = ZernikeSeries(rows, a)
    assert np.allclose(series(X, Y), zernike_sum(rows, a, X, Y), rtol=0, atol=1e-15)
    x, y = np.append(rng.uniform(-50, 50, 200), 0.0), np.append(rng.uniform(-50, 50, 200), 0.0)
    h = 1e-3
    gx, gy = series.gradient(x, y)
    assert np.allclose(gx, (series(x + h, y) - series(x - h, y)) / (2 * h), rtol=1e-6, atol=1e-12)
    assert np.allclose(gy, (series(x, y + h) - series(x, y - h)) / (2 * h), rtol=1e-6, atol=1e-12)


def test_each_model_reaches_its_drawn_rms_over_the_disk():
    """The RMS a model draws is the surface's RMS over the aperture: against a polar quadrature
    of the built deformation over the disk (all four kinds) and, where the surface has one, the
    closed form of its parameters: sqrt(sum c^2) for Noll-normalised Zernike terms,
    |A| / sqrt(2 (p + 1)) for the rim astigmatism. A 128 x 128 map samples the disk to about
    1 %, so that is the tolerance."""
    spec = parse_spec(DEMO_TEXT.replace("grid_n = 48", "grid_n = 128"), base=ROOT / "scenes")
    grid, a = spec.grid, 0.5 * spec.scene.D
    for model in spec.models:
        seen = 0
        for k in range(12):
            deformation, params = model.draw(np.random.default_rng(k), grid)
            if deformation is None:
                assert params["present"] == 0 and params["rms"] == 0.0
                continue
            seen += 1
            lo, hi = model.rms.support
            assert lo <= params["rms"] <= hi
            assert disk_rms(deformation, a, grid.layout) == pytest.approx(params["rms"], rel=0.01), model.kind
            if model.kind == "zernike":
                assert np.sqrt(np.sum(params["coefficient"] ** 2)) == pytest.approx(params["rms"], rel=0.01)
            if model.kind == "gravity":
                exact = abs(params["amplitude"]) / np.sqrt(2 * (params["exponent"] + 1))
                assert exact == pytest.approx(params["rms"], rel=0.01)
            if seen == 3:
                break
        assert seen == 3, model.kind


def test_drawn_rms_values_follow_the_spec_laws(coarse_demo):
    draws = [draw_sample(coarse_demo, i).params for i in range(coarse_demo.samples)]
    zernike = np.array([p["zernike_rms"] for p in draws]) * 1e6
    assert stats.kstest(zernike, stats.uniform(50, 150).cdf).pvalue > 1e-3
    present = np.array([p["bumps_present"] for p in draws])
    n = len(present)
    assert abs(present.mean() - 0.75) < 4 * np.sqrt(0.75 * 0.25 / n)
    bumps = np.log(np.array([p["bumps_rms"] for p in draws if p["bumps_present"]]) * 1e6)
    assert stats.kstest(bumps, stats.uniform(np.log(10), np.log(6)).cdf).pvalue > 1e-3
    exponent = np.array([p["gravity_exponent"] for p in draws])
    assert stats.kstest(exponent, stats.uniform(2.5, 1.5).cdf).pvalue > 1e-3
    counts = np.array([np.isfinite(p["bumps_x"]).sum() for p in draws if p["bumps_present"]])
    assert set(np.unique(counts)) == {2, 3, 4, 5, 6}
    # absent bumps leave their parameters NaN
    assert all(np.isnan(p["bumps_x"]).all() for p in draws if not p["bumps_present"])


def test_samples_regenerate_alone_and_differ(coarse_demo):
    a = draw_sample(coarse_demo, 17)
    b = draw_sample(coarse_demo, 17)
    c = draw_sample(coarse_demo, 17, seed=sample_seed(coarse_demo.seed, 17))
    other = draw_sample(coarse_demo, 18)
    grid = coarse_demo.grid
    assert np.array_equal(grid.evaluate(a.deformation), grid.evaluate(b.deformation), equal_nan=True)
    assert np.array_equal(grid.evaluate(a.deformation), grid.evaluate(c.deformation), equal_nan=True)
    assert not np.allclose(grid.evaluate(a.deformation), grid.evaluate(other.deformation), equal_nan=True)
    seeds = {sample_seed(coarse_demo.seed, i) for i in range(coarse_demo.samples)}
    assert len(seeds) == coarse_demo.samples


def test_a_model_draws_the_same_whatever_models_follow_it():
    alone = DEMO_TEXT[: DEMO_TEXT.index("[[errors]]\ntype = \"bumps\"")]  # the zernike entry only
    full = load_spec(ROOT / "scenes" / "dataset_demo.toml")
    part = parse_spec(alone, base=ROOT / "scenes")
    assert [m.kind for m in part.models] == ["zernike"]
    for i in range(4):
        assert np.array_equal(draw_sample(part, i).params["zernike_coefficient"],
                              draw_sample(full, i).params["zernike_coefficient"])


def test_validation_split_is_fixed_by_the_seed(coarse_demo):
    mask = validation_mask(coarse_demo)
    assert mask.sum() == round(0.25 * coarse_demo.samples)
    assert np.array_equal(mask, validation_mask(coarse_demo))
    reseeded = parse_spec(DEMO_TEXT.replace("seed = 20240917", "seed = 5"), base=ROOT / "scenes")
    assert validation_mask(reseeded).sum() == 2


def test_memo_returns_the_wrapped_values_bit_for_bit(coarse_demo):
    from raysim.maps.sphere import SphereGrid
    from raysim.optics import go
    from raysim.surface.mesh import paraboloid

    deformation = draw_sample(coarse_demo, 3).deformation
    memo = Memo(deformation)
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-40, 40, 300), rng.uniform(-40, 40, 300)
    for _ in range(2):  # the second round is answered from the memo
        assert np.array_equal(memo(x, y), deformation(x, y))
        assert all(np.array_equal(p, q) for p, q in zip(memo.gradient(x, y), deformation.gradient(x, y),
                                                         strict=True))
    assert np.array_equal(memo(x[:10], y[:10]), deformation(x[:10], y[:10]))  # new points
    ideal = paraboloid(110.0, 33.0, 2.0)
    grid = SphereGrid(10.0, 10, 24)
    plain = go.trace(ideal.deformed(deformation), grid).intensity
    cached = go.trace(ideal.deformed(Memo(deformation)), grid).intensity
    assert np.array_equal(plain, cached)
