"""A dataset whose scene has a probe reads its samples with it, as ``simulate`` does."""

from __future__ import annotations

import numpy as np

from raysim.dataset import parse_spec
from raysim.dataset.engine import ideal_intensity
from raysim.simulate import simulate
from tests.raysim.dataset.conftest import ROOT, small_demo_text

PROBE = "[scene.probe]\npolarization_deg = 90.0\npattern_q = 2.0\n\n[[errors]]"


def test_dataset_samples_are_read_by_the_scenes_probe():
    text = small_demo_text(measurement=False).replace("[[errors]]", PROBE, 1)
    spec = parse_spec(text, base=ROOT / "scenes")
    assert not spec.scene.probe.ideal
    ideal = ideal_intensity(spec, 0)
    np.testing.assert_allclose(ideal, simulate(spec.scene, "go")["intensity_ideal"].values,
                               rtol=1e-12, atol=1e-15)
    plain = ideal_intensity(parse_spec(small_demo_text(measurement=False),
                                       base=ROOT / "scenes"), 0)
    # a cross-polar probe: a part of |E|^2, up to 43 % near this deep dish's rim (80 deg)
    lit = plain > 0
    assert np.max(ideal[lit] / plain[lit]) < 0.5 and np.median(ideal[lit] / plain[lit]) < 0.1
