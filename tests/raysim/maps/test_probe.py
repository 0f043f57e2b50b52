"""The probe's pattern, co-polar direction and FieldMap attributes (raysim.maps.probe)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from raysim.errors import FieldMapError, ProbeError
from raysim.maps.fieldmap import fieldmap, load, save
from raysim.maps.probe import IDEAL, Probe, probe_of
from raysim.maps.sphere import SphereGrid


def test_cos_q_pattern_values():
    probe = Probe(None, 3.0)
    # cos 60 deg = 1/2; nothing from behind the probe; q = 0 hears every direction alike
    assert probe.pattern(math.radians(60.0)) == pytest.approx(0.125, rel=1e-12)
    assert probe.pattern(0.0) == 1.0 and probe.pattern(math.radians(120.0)) == 0.0
    assert np.all(Probe(None, 0.0).pattern(np.radians([0.0, 90.0, 180.0])) == 1.0)


def test_table_pattern_interpolates_and_holds_its_ends():
    probe = Probe(0.0, table=((0.0, 1.0), (math.radians(20.0), 0.5), (math.radians(40.0), 0.0)))
    values = probe.pattern(np.radians([0.0, 10.0, 30.0, 40.0, 90.0]))
    np.testing.assert_allclose(values, [1.0, 0.75, 0.25, 0.0, 0.0], atol=1e-15)
    late = Probe(None, table=((math.radians(10.0), 0.8), (math.radians(20.0), 0.6)))
    assert late.pattern(0.0) == pytest.approx(0.8)


def test_co_polar_direction():
    """p_t is unit, transverse to the wave, in the plane of p and d, on p's side; zero when
    p lies along d; and |p_t . E|^2 = (p . E)^2 / (1 - (p . d)^2) for a transverse E."""
    rng = np.random.default_rng(7)
    d = rng.standard_normal((50, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    probe = Probe(math.radians(30.0))
    p = probe.p_hat
    pt = probe.co_polar(d)
    np.testing.assert_allclose(np.linalg.norm(pt, axis=1), 1.0, rtol=1e-14)
    np.testing.assert_allclose(np.sum(pt * d, axis=1), 0.0, atol=1e-14)
    np.testing.assert_allclose(np.einsum("ij,ij->i", np.cross(p, d), pt), 0.0, atol=1e-14)
    assert np.all(pt @ p > 0)
    E = np.cross(d, rng.standard_normal((50, 3)))  # transverse to d
    np.testing.assert_allclose(probe.power(E, d), (E @ p) ** 2 / (1 - (d @ p) ** 2), rtol=1e-12)
    assert np.all(probe.co_polar(np.array([p, -p])) == 0.0)
    assert IDEAL.co_polar(d) is None


def test_ideal_meter_reads_e_squared():
    E = np.array([[1 + 2j, 0.5, -1j]])
    assert IDEAL.ideal and IDEAL.attrs() == {}
    assert IDEAL.power(E, np.array([[0.0, 0.0, 1.0]]))[0] == pytest.approx(1 + 4 + 0.25 + 1)


@pytest.mark.parametrize("probe", [
    Probe(math.radians(90.0), 2.5),
    Probe(None, table=((0.0, 1.0), (math.radians(15.0), 0.7), (math.radians(60.0), 0.05))),
])
def test_probe_attributes_survive_a_netcdf_file(tmp_path: Path, probe: Probe):
    grid = SphereGrid(3.0, 4, 6)
    ones = np.ones((4, 6))
    path = save(fieldmap(grid, ones, ones, focal_length=8.0, diameter=20.0, frequency_hz=1e9,
                         method="go", sampling="cell_mean", attrs=probe.attrs()), tmp_path / "f.nc")
    ds = load(path)
    assert probe_of(ds) == probe
    assert ds.attrs["probe"] == probe.describe()
    bare = save(fieldmap(grid, ones, ones, focal_length=8.0, diameter=20.0, frequency_hz=1e9,
                         method="go", sampling="cell_mean"), tmp_path / "bare.nc")
    assert probe_of(load(bare)) is IDEAL


@pytest.mark.parametrize("kwargs, message", [
    ({"q": -1.0}, "q must be a number in 0..1000"),
    ({"q": math.nan}, "q must be a number"),
    ({"table": ((0.0, 1.0), (0.0, 0.5))}, "must increase from row to row"),
    ({"table": ((0.0, 1.0), (4.0, 0.5))}, "must lie in 0..180 deg"),
    ({"table": ((0.0, 1.0), (0.5, -0.5))}, "relative powers must be >= 0"),
    ({"table": ((0.0, -1.0), (0.5, 1.0))}, "relative powers must be >= 0"),
    ({"table": ((0.0, 0.0), (math.pi / 2, 0.0))}, "a pattern needs some positive power"),
    ({"table": ((0.1, 0.0), (0.2, 0.0), (0.3, 0.0))}, "a pattern needs some positive power"),
    ({"table": ((0.0, 1.0),)}, "at least two"),
    ({"q": 2.0, "table": ((0.0, 1.0), (0.5, 0.5))}, "not both"),
])
def test_not_a_probe(kwargs, message):
    with pytest.raises(ProbeError, match=message):
        Probe(**kwargs)


def test_unusable_probe_attributes():
    with pytest.raises(FieldMapError, match="unusable probe attributes"):
        probe_of({"probe_pattern": "table", "probe_pattern_angle": [0.0, 1.0]})
    with pytest.raises(FieldMapError, match="unusable probe attributes"):
        probe_of({"probe_pattern": "cos^q", "probe_pattern_q": -2.0})


def test_an_all_zero_pattern_in_a_scene_is_refused_in_one_line():
    from raysim.errors import SceneError
    from raysim.scene.scene import parse_scene

    base = ("[dish]\ndiameter_m = 20.0\nfocal_length_m = 8.0\n[source]\nfrequency_hz = 1e9\n"
            "[sphere]\nradius_m = 2.0\n[probe]\npattern = {rows}\n")
    with pytest.raises(SceneError, match="a pattern needs some positive power") as info:
        parse_scene(base.format(rows="[[0.0, 0.0], [90.0, 0.0]]"), source="p.toml")
    assert "\n" not in str(info.value) and str(info.value).startswith("p.toml: ")
    # one positive row is a pattern: it reads g(alpha) interpolated towards it
    probe = parse_scene(base.format(rows="[[0.0, 0.0], [90.0, 1.0]]"), source="p.toml").probe
    assert probe.pattern(math.radians(45.0)) == pytest.approx(0.5, rel=1e-12)
