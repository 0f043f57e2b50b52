"""The whole inversion on exact GO data from the independent reference trace."""

import numpy as np
import pytest

from raysim.errors import FieldMapError
from solver import metrics
from solver.aperture import ApertureGrid
from solver.boundary import RimTargets
from solver.errors import RimTargetsError, SolverError
from solver.invert import invert
from tests.reference_go import paper_delta, reference_forward
from tests.solver.conftest import A, harmonic_delta


def third(x, y):
    return paper_delta(x, y, scale=1 / 3)


def linear(field, truth, **options):
    return invert(field, refine_iterations=0, truth=truth, **options)


def test_the_linear_equation_errs_as_the_design_says(paper_field):
    """Exact GO data, linear equation: about 9 % RRMS, almost all piston, tilt and focus."""
    result = linear(paper_field, paper_delta)
    assert 0.08 < result.attrs["rrms"] < 0.105
    removed = linear(paper_field, paper_delta, remove="piston,tilt,focus")
    assert removed.attrs["rrms"] < 0.01
    assert removed.attrs["removed_terms"] == "piston,tilt,focus"
    assert removed.attrs["removed_piston_m"] > 1e-4          # the error is mostly piston
    assert abs(removed.attrs["removed_tilt_x_rad"]) < 1e-12  # Eq. 8 is round


def test_the_linear_error_grows_with_the_square_of_the_deformation(paper_field,
                                                                  paper_field_third):
    big = linear(paper_field, paper_delta).attrs["rms_m"]
    small = linear(paper_field_third, third).attrs["rms_m"]
    assert 1.8 < np.log(big / small) / np.log(3.0) < 2.5


@pytest.mark.slow
def test_go_refinement_removes_the_linearisation_error(paper_field):
    result = invert(paper_field, refine_iterations=2, truth=paper_delta,
                    forward=reference_forward(order=2))
    assert result.attrs["rrms"] < 0.002                      # the paper: 4.06 %
    updates = [float(v) for v in result.attrs["refine_update_rms_m"].split(",")]
    assert updates[0] > 1e-4 > 1e-5 > result.attrs["rms_m"]


@pytest.mark.slow
def test_refinement_never_returns_a_map_that_fits_the_data_worse(paper_field):
    # on a 16-point grid the updates cannot represent the surface: the first raised the misfit,
    # its shortened steps lowered it too little, and steps kept anyway made the map worse than
    # the linear answer (240 -> 697 um RMS); the loop keeps the map before the update
    kept = invert(paper_field, N=16, refine_iterations=4, truth=paper_delta,
                  forward=reference_forward(order=2))
    assert kept.attrs["refine_stopped"].startswith("misfit rose at update 1 of 4")
    plain = linear(paper_field, paper_delta, N=16)
    np.testing.assert_array_equal(kept["deformation"].values, plain["deformation"].values)
    # where the updates help, the loop runs as asked
    fine = invert(paper_field, refine_iterations=2, truth=paper_delta, forward=reference_forward(order=2))
    assert fine.attrs["refine_stopped"] == "no: every iteration ran"


def test_any_constant_gain_gives_the_same_map_when_estimated(paper_field):
    scaled = paper_field.copy(deep=True)
    scaled["intensity"] = scaled["intensity"] * 1.7
    a = linear(paper_field, None, remove="focus", gain="power")
    b = linear(scaled, None, remove="focus", gain="power")
    assert np.isclose(b.attrs["gain"], 1.7, rtol=1e-9)
    assert not b.attrs["gain_known"] and a.attrs["gain_mode"] == "power"
    np.testing.assert_allclose(b["deformation"].values, a["deformation"].values,
                               rtol=0, atol=1e-12)
    trusting = linear(scaled, None, remove="focus", gain="known")
    assert trusting.attrs["gain_known"] and trusting.attrs["gain"] == 1.0
    grid = ApertureGrid(110.0, 256)
    assert metrics.rms_error(grid, trusting["deformation"].values, a["deformation"].values) > 1e-5


def test_missing_samples_are_filled_and_reported(paper_field):
    holed = paper_field.copy(deep=True)
    values = holed["intensity"].values
    holes = np.random.default_rng(11).random(values.shape) < 0.02
    values[holes] = np.nan
    holed["intensity"] = (("theta", "phi"), values)
    clean = linear(paper_field, paper_delta)
    got = linear(holed, paper_delta)
    assert got.attrs["samples_missing"] == int(holes[:79].sum())
    assert abs(got.attrs["rrms"] - clean.attrs["rrms"]) < 0.003
    # a cell the ideal reflector leaves dark is a missing sample too (its FA of -1, a deep
    # bump, took the map's peak-to-peak from 1.8 to 10 mm for one such cell)
    dark = paper_field.copy(deep=True)
    dark["intensity_ideal"].values[holes] = 0.0
    got = linear(dark, paper_delta)
    assert got.attrs["samples_missing"] == int(holes[:79].sum())
    assert abs(got.attrs["rrms"] - clean.attrs["rrms"]) < 0.003


def test_rim_targets_fix_the_unobservable_harmonic_part(harmonic_field):
    phi = np.linspace(0, 2 * np.pi, 64, endpoint=False) + 0.01
    x, y = 0.995 * A * np.cos(phi), 0.995 * A * np.sin(phi)
    rim = RimTargets(x, y, harmonic_delta(x, y), source="test targets")
    without = linear(harmonic_field, harmonic_delta)
    assert without.attrs["harmonic_part"] == "unobservable"
    assert without.attrs["harmonic_observable"] == 0
    assert without.attrs["rms_m"] > 50e-6                     # the astigmatism is missed
    with_rim = linear(harmonic_field, harmonic_delta, rim=rim)
    assert with_rim.attrs["harmonic_part"] == "fixed by rim targets"
    assert "64 points from test targets" in with_rim.attrs["boundary"]
    assert with_rim.attrs["rms_m"] < 15e-6
    assert with_rim.attrs["rim_harmonic_order"] == 12  # the fit's cap: nothing said


def test_rim_targets_on_half_the_rim_say_how_little_of_the_harmonic_part_they_fix(harmonic_field):
    """16 targets over half the rim fix the harmonic part to order 1 only (the widest gap, pi,
    allows no more), and the map carried the rest of its astigmatism while the SurfaceMap said
    "fixed by rim targets". The order is recorded, and the summary warns under order 3."""
    from solver.run import summary

    phi = np.linspace(0, np.pi, 16)
    x, y = 0.995 * A * np.cos(phi), 0.995 * A * np.sin(phi)
    half = linear(harmonic_field, harmonic_delta, rim=RimTargets(x, y, harmonic_delta(x, y)))
    assert half.attrs["rim_harmonic_order"] == 1
    assert half.attrs["rms_m"] > 50e-6  # the astigmatism (order 2) is still missed
    text = "\n".join(summary(half))
    assert "WARNING: the rim targets fix the harmonic part to order 1 only" in text


def test_intensity_std_gives_a_deformation_std_that_matches_the_scatter(paper_field, sphere):
    sigma = 0.01 * np.log(10) / 10                            # 0.01 dB, relative
    grid = ApertureGrid(110.0, 96)
    clean = invert(paper_field, N=96, refine_iterations=0, truth=None)["deformation"].values
    scatter = []
    result = None
    for seed in range(3):
        noisy = paper_field.copy(deep=True)
        i = noisy["intensity"].values
        noisy["intensity"] = (("theta", "phi"),
                              i * (1 + sigma * np.random.default_rng(seed).standard_normal(i.shape)))
        noisy["intensity_std"] = (("theta", "phi"), sigma * i, {"units": "1"})
        result = invert(noisy, N=96, refine_iterations=0, truth=None, uncertainty_samples=24,
                        seed=seed + 100)
        scatter.append(result["deformation"].values - clean)
    assert result.attrs["noise_source"] == "intensity_std"
    assert np.isclose(result.attrs["noise_relative_std"], sigma, rtol=0.05)
    predicted = metrics.rms(grid, result["deformation_std"].values)
    observed = np.sqrt(np.mean([metrics.rms(grid, s) ** 2 for s in scatter]))
    assert 0.6 < predicted / observed < 1.6
    # and the summary says it (it said nothing of the noise's spread)
    from solver.run import summary

    (line,) = [t for t in summary(result) if t.startswith("noise: ")]
    assert f"{predicted * 1e6:.2f} um RMS" in line


def test_an_intensity_std_with_gaps_spreads_the_map_as_one_without(paper_field):
    """NaN in the stated intensity_std counted as no noise: with every other phi column NaN
    the stated spread fell from 93 to 62 um on the same readings; all NaN stated "0.00 um"
    (deformation_std 4e-19 m) while the noise was estimated from the data."""
    sigma = 0.01 * np.log(10) / 10                            # 0.01 dB, relative
    grid = ApertureGrid(110.0, 96)
    noisy = paper_field.copy(deep=True)
    i = noisy["intensity"].values
    noise = sigma * np.random.default_rng(7).standard_normal(i.shape)
    noisy["intensity"] = (("theta", "phi"), i * (1 + noise))
    noisy["intensity_std"] = (("theta", "phi"), sigma * i, {"units": "1"})

    def spread(std):
        field = noisy.copy(deep=True)
        field["intensity_std"] = (("theta", "phi"), std, {"units": "1"})
        out = invert(field, N=96, refine_iterations=0, truth=None, uncertainty_samples=24, seed=3)
        return out, (metrics.rms(grid, out["deformation_std"].values)
                     if "deformation_std" in out else None)

    _, full = spread(sigma * i)
    gaps = sigma * i
    gaps[:, 1::2] = np.nan
    _, gapped = spread(gaps)
    assert 0.85 < gapped / full < 1.15
    # all NaN states nothing: the noise is estimated from the readings, and the map's spread
    # under it is measured and kept (the same 0.01 dB, so about the stated figure)
    none, nothing = spread(np.full_like(i, np.nan))
    assert none.attrs["noise_source"].startswith("estimated")
    assert 0.6 < nothing / full < 1.4
    # a std of zero everywhere (a placeholder) stated a spread of 0.00 um; it states none
    zero, nil = spread(np.zeros_like(i))
    assert zero.attrs["noise_source"].startswith("estimated")
    assert 0.6 < nil / full < 1.4
    # zero in some cells: those take the scan's noise, the others keep theirs
    some = sigma * i
    some[:, 1::2] = 0.0
    _, partly = spread(some)
    assert 0.85 < partly / full < 1.15


def test_without_a_stated_std_the_noise_spread_is_predicted_and_a_noisy_map_is_flagged(
        paper_field):
    """With no intensity_std the map said nothing of the noise: 0.05 dB per reading at 0.9 F
    on a 50 m dish made a map 572 um off a 200 um peak-to-peak surface, exit 0. The spread is
    now measured by the Monte Carlo with the noise estimated in the scan, checked here against
    the scatter of the inversion over independent noisy scans, and a map whose spread is more
    than half its own RMS is flagged; clean data skip the Monte Carlo (the budget screens)."""
    from solver.run import summary

    grid = ApertureGrid(110.0, 96)
    clean = invert(paper_field, N=96, refine_iterations=0, truth=None)
    assert "noise_warning" not in clean.attrs and "noise_map_rms_m" not in clean.attrs

    def noisy_map(db, seed):
        field = paper_field.copy(deep=True)
        i = field["intensity"].values
        draw = np.random.default_rng(seed).standard_normal(i.shape)
        field["intensity"] = (("theta", "phi"), i * 10 ** (db * draw / 10))
        return invert(field, N=96, refine_iterations=0, truth=None)

    maps = [noisy_map(0.01, seed) for seed in range(3)]
    observed = np.sqrt(np.mean([metrics.rms(grid, m["deformation"].values
                                             - clean["deformation"].values) ** 2 for m in maps]))
    predicted = maps[0].attrs["noise_map_rms_m"]
    assert maps[0].attrs["noise_source"].startswith("estimated")
    assert 0.6 < predicted / observed < 1.6
    assert "noise_warning" not in maps[0].attrs                  # 0.01 dB: about 90 of 330 um
    (line,) = [t for t in summary(maps[0]) if t.startswith("noise: ")]
    assert f"spreads the map by {predicted * 1e6:.2f} um RMS" in line

    loud = noisy_map(0.1, 5)
    assert loud.attrs["noise_map_rms_m"] > 0.5 * metrics.rms(grid, loud["deformation"].values)
    assert any(t.startswith("WARNING: the readings' noise (0.1 dB per cell)")
               for t in summary(loud))


def test_a_refined_map_of_noise_is_flagged_with_a_trusted_gain(paper_field):
    """0.5 dB per reading with the gain trusted: the refinement fits the noise's nonlinear
    part and the map comes out several times the noise's spread off the truth; its RMS, so
    inflated, hid the warning, which now weighs the spread against the linear map too."""
    field = paper_field.copy(deep=True)
    i = field["intensity"].values
    draw = np.random.default_rng(2).standard_normal(i.shape)
    field["intensity"] = (("theta", "phi"), i * 10 ** (0.5 * draw / 10))
    grid = ApertureGrid(110.0, 48)
    clean = invert(paper_field, N=48, refine_iterations=1, gain="known", truth=None)
    noisy = invert(field, N=48, refine_iterations=1, gain="known", truth=None)
    error = metrics.rms(grid, noisy["deformation"].values - clean["deformation"].values)
    assert error > 2 * noisy.attrs["noise_map_rms_m"]  # the spread alone does not bound it
    assert "mostly noise" in noisy.attrs["noise_warning"]


def test_bad_requests_raise_specific_errors(paper_field):
    with pytest.raises(SolverError, match="gain"):
        invert(paper_field, gain="sometimes")
    with pytest.raises(SolverError, match="refine"):
        invert(paper_field, refine_iterations=-1)
    with pytest.raises(SolverError, match="unknown solver"):
        invert(paper_field, solver="cholesky")
    with pytest.raises(SolverError, match="truth has shape"):
        invert(paper_field, refine_iterations=0, truth=np.zeros((3, 3)))
    phi = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    rim = RimTargets(A * np.cos(phi), A * np.sin(phi), np.zeros(8))
    with pytest.raises(SolverError, match="fft"):
        invert(paper_field, solver="fft", rim=rim)
    with pytest.raises(RimTargetsError, match="at least 8"):
        invert(paper_field, rim=RimTargets(A * np.cos(phi[:5]), A * np.sin(phi[:5]), phi[:5] * 0))
    with pytest.raises(FieldMapError, match="intensity_ideal"):
        invert(paper_field.drop_vars("intensity_ideal"))
    with pytest.raises(SolverError, match="off axis"):
        invert(paper_field.assign_attrs(incidence_theta=np.radians(2.0)))
    for not_a_fieldmap in ("f.nc", paper_field.intensity, {}):
        with pytest.raises(FieldMapError, match="invert takes a FieldMap"):
            invert(not_a_fieldmap)
    # no ideal power in any cell: a 4 m map came back (the truth peaks at 1.2 mm)
    with pytest.raises(FieldMapError, match="missing"):
        invert(paper_field.assign(intensity_ideal=paper_field.intensity_ideal * 0), refine_iterations=0)
    # each of these returned a map (all NaN, all zero, or 1e60 m) without a word
    for bad, says in (({"tol": -1.0}, "tolerance"), ({"tol": float("nan")}, "tolerance"),
                      ({"tol": 10.0}, "tolerance"), ({"tol": "1e-10"}, "tolerance"),
                      ({"solver": "sor", "omega": -1.0}, "relaxation"),
                      ({"solver": "sor", "omega": 0.0}, "relaxation"),
                      ({"solver": "sor", "omega": 2.0}, "relaxation"),
                      ({"seed": -1}, "seed"), ({"seed": 1.5}, "seed"),
                      ({"uncertainty_samples": "3"}, "Monte Carlo"),
                      ({"device": "tpu"}, "unknown device 'tpu'")):
        with pytest.raises(SolverError, match=says):
            invert(paper_field, refine_iterations=0, **bad)


def test_options_object_gives_the_keywords_answer_and_checks_itself(paper_field):
    """invert(field, options=InvertOptions(...)) is invert(field, **same keywords); a bad
    setting fails when the options are made, before any data is read."""
    from solver.invert import InvertOptions

    keywords = invert(paper_field, N=64, refine_iterations=0, remove="piston, focus", truth=None)
    options = InvertOptions(N=64, refine_iterations=0, remove="piston, focus")
    assert options.terms == ("piston", "focus")
    again = invert(paper_field, options=options, truth=None)
    np.testing.assert_array_equal(again["deformation"].values, keywords["deformation"].values)
    assert again.attrs["removed_terms"] == keywords.attrs["removed_terms"] == "piston,focus"
    for bad in ({"solver": "jacobi"}, {"gain": "sometimes"}, {"refine_iterations": -1},
                {"model": "fdtd"}, {"weights": "some"}, {"remove": "coma"},
                {"solver": "fft", "rim": RimTargets(np.ones(8), np.ones(8), np.zeros(8))}):
        with pytest.raises(SolverError):
            InvertOptions(**bad)
    for harmonics in (2.5, 0, -3, True):  # a bare TypeError, or blame on the targets' spacing
        with pytest.raises(SolverError, match=r"max_harmonics\) must be an integer in 1\.\.100"):
            InvertOptions(max_harmonics=harmonics)


def _bump_scene(amplitude_um: float) -> str:
    return ('name = "bump"\n[dish]\ndiameter_m = 60\nfocal_length_m = 24\nresolution_m = 0.25\n'
            f'[[deformation]]\ntype = "bumps"\n[[deformation.bumps]]\nx_m = 5\ny_m = -3\n'
            f'amplitude_um = {amplitude_um}\nsigma_m = 2.0\n[source]\nfrequency_hz = 3e8\n'
            '[sphere]\nradius_m = 7.2\nn_theta = 45\nn_phi = 180\n')


@pytest.mark.parametrize(("amplitude_um", "warned"), [(100.0, False), (20_000.0, True)])
def test_a_map_whose_model_does_not_reproduce_the_scan_is_said_so(amplitude_um, warned):
    """A 20 mm bump of 2 m is past GO's linear range: the default map came back with 34 % of
    error, its sign wrong at the bump, the model leaving 39 % of the data's FA unexplained,
    and the summary said nothing. A 100 um bump's model fits the data to a few per cent."""
    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate
    from solver.run import summary

    surface = invert(simulate(parse_scene(_bump_scene(amplitude_um)), method="go"))
    lines = summary(surface)
    assert any(line.startswith("WARNING: the model leaves") for line in lines) == warned
    if not warned:
        assert surface.attrs["refine_misfit_share"] < 0.07
