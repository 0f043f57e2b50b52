"""Dataset specs: parsing, unit conversion at the edge, one-line errors, the fingerprint."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from raysim.dataset import DatasetError, load_spec, parse_spec
from raysim.dataset.distributions import parse_distribution
from raysim.dataset.toml_text import dumps
from raysim.errors import RaysimError

ROOT = Path(__file__).resolve().parents[3]
DEMO = ROOT / "scenes" / "dataset_demo.toml"

SMALL = """
samples = 4
seed = 7
[scene]
[scene.dish]
diameter_m = 20.0
focal_length_m = 8.0
resolution_m = 1.0
[scene.source]
frequency_hz = 1e9
[scene.sphere]
radius_m = 3.0
n_theta = 8
n_phi = 16
[[errors]]
type = "zernike"
rms_um = { uniform = [10.0, 20.0] }
"""


def test_demo_spec_loads_in_si_units():
    spec = load_spec(DEMO)
    assert spec.samples == 8 and spec.method == "go"
    assert spec.scene.D == 110.0 and spec.scene.F == 33.0
    assert spec.frequencies == (0.3e9,)
    kinds = [m.kind for m in spec.models]
    assert kinds == ["zernike", "bumps", "panel_rigid", "gravity"]
    zernike, bumps, _, gravity = spec.models
    assert zernike.rms.support == pytest.approx((50e-6, 200e-6))  # um -> m
    assert bumps.sigma.support == (1.5, 4.0) and bumps.probability == 0.75
    assert gravity.angle.a == pytest.approx(math.pi / 2)  # deg -> rad
    assert spec.n_validation == 2
    assert spec.grid.x[0] == pytest.approx(-55.0 + 110.0 / 48 / 2)


def test_inline_scene_and_scene_file_are_the_same_scene(tmp_path):
    scene_file = ROOT / "scenes" / "paper_go.toml"
    by_file = parse_spec(f'samples = 2\nseed = 1\nscene = "{scene_file}"\n', base=tmp_path)
    table = tomllib.loads(scene_file.read_text())
    inline = parse_spec(dumps({"samples": 2, "seed": 1, "scene": table}), base=tmp_path)
    for field in ("dish", "source", "sphere", "subdivisions"):
        assert getattr(inline.scene, field) == getattr(by_file.scene, field)
    assert inline.scene.deformation.describe() == by_file.scene.deformation.describe()
    assert inline.fingerprint == by_file.fingerprint  # content, not spelling


def test_toml_text_round_trips_nested_tables():
    table = {"name": 'a "quoted" name', "n": 3, "x": 1e-7, "flag": True,
             "dish": {"diameter_m": 110.0, "list": [[1, 2, 3.5]]},
             "deformation": [{"type": "bumps", "bumps": [{"x_m": 1.0, "y_m": -2.0}]},
                             {"type": "zernike", "terms": [[2, 2, 100.0]]}]}
    assert tomllib.loads(dumps(table)) == table


def test_fingerprint_ignores_comments_but_not_content():
    base = parse_spec(SMALL)
    assert parse_spec("# a comment\n" + SMALL.replace("seed = 7", "seed = 7   # same")).fingerprint \
        == base.fingerprint
    assert parse_spec(SMALL.replace("seed = 7", "seed = 8")).fingerprint != base.fingerprint
    assert parse_spec(SMALL.replace("n_phi = 16", "n_phi = 32")).fingerprint != base.fingerprint


@pytest.mark.parametrize(("change", "message"), [
    (("seed = 7", "sede = 7"), "did you mean 'seed'"),
    (("samples = 4", "samples = 0"), "'samples' must be >= 1, got 0"),
    (('type = "zernike"', 'type = "warp"'), "errors[0].type' must be one of"),
    (("{ uniform = [10.0, 20.0] }", "{ normal = [10.0, 5.0] }"), "must stay >= 0"),
    (("{ uniform = [10.0, 20.0] }", "{ uniform = [20.0, 10.0] }"), "needs lo <= hi"),
    (("{ uniform = [10.0, 20.0] }", "{ gauss = [1.0, 2.0] }"), "must name one law"),
    (('type = "zernike"', 'type = "panel_rigid"'), "needs a [scene.panels] layout"),
    (("seed = 7", "seed = 7\nfrequencies_hz = [0.3]"), "in Hz, not GHz"),
    (("seed = 7", 'seed = 7\nmethod = "ray"'), "'method' must be one of"),
    (("seed = 7", 'seed = 7\nmethod = "po"\nfrequencies_hz = [1e9, 2e11]'),
     "source samples per reflector"),
    (("seed = 7", 'seed = 7\ndtype = "int8"'), "'dtype' must be one of"),
    (("n_phi = 16", "n_phi = -1"), "[scene]"),
])
def test_spec_defects_raise_one_line(change, message):
    with pytest.raises(RaysimError) as info:  # DatasetError, or SceneError inside [scene]
        parse_spec(SMALL.replace(*change), source="bad.toml")
    text = str(info.value)
    assert message in text and "\n" not in text and text.startswith("bad.toml")


def test_mesh_scenes_are_refused(tmp_path):
    mesh = tmp_path / "dish.stl"
    mesh.write_text("solid empty\nendsolid empty\n")
    text = SMALL.replace("diameter_m = 20.0", f'diameter_m = 20.0\nmesh = "{mesh}"')
    with pytest.raises(DatasetError, match="generated paraboloid"):
        parse_spec(text)


def test_distribution_laws_draw_inside_their_support():
    rng = np.random.default_rng(3)
    for value, lo, hi in (({"uniform": [2, 5]}, 2, 5), ({"loguniform": [1, 100]}, 1, 100),
                          ({"integers": [1, 3]}, 1, 3), (4.5, 4.5, 4.5)):
        dist = parse_distribution(value, "k", integer=isinstance(value, dict) and "integers" in value)
        draws = np.asarray(dist.draw(rng, 500), dtype=float)
        assert draws.min() >= lo and draws.max() <= hi
    integers = parse_distribution({"integers": [1, 3]}, "k", integer=True).draw(rng, 3000)
    assert set(np.unique(integers)) == {1, 2, 3}  # both ends included
