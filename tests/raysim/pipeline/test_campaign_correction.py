"""``raysim campaign`` on a panelled dish ends with the correction: commands, the command error
each actuator inherits from the budget, beside the error the commands really have."""

import csv
from pathlib import Path

import numpy as np

from raysim.pipeline.campaign import run_campaign
from tests.hardware.conftest import write_plan
from tests.raysim.pipeline.test_campaign import SCENE

PANELS = """
[panels]
ring_edges_m = [0.0, 13.75, 27.5, 41.25, 55.0]
panels_per_ring = [6, 12, 18, 24]
"""


def test_a_panelled_campaign_writes_commands_with_their_inherited_error(tmp_path: Path):
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE + PANELS)
    plan = write_plan(tmp_path, theta_max=80.0, theta_step=5.0, phi_step=10.0, samples=1,
                      noise=0.01, every=4)
    result = run_campaign(scene, plan, tmp_path / "c", rim=32, N=64, refine=1)
    text = (result.folder / "commands.csv").read_text()
    assert "a positive command moves the surface" in text
    # what the map may not hold (here: the panel pistons GO does not see) is in the file the
    # crew loads, as raysim correct writes it; the campaign's commands.csv left it out
    from raysim.maps.surfacemap import load
    from solver.correction_io import map_caveats

    caveats = map_caveats(load(result.folder / "surface.nc").attrs, 24 + 18 + 12 + 6)
    assert caveats and all(" ".join(c.split()) in text for c in caveats)
    rows = list(csv.DictReader(line for line in text.splitlines() if not line.startswith("#")))
    assert len(rows) == 97
    std = np.array([float(r["command_std_um"]) for r in rows])
    assert np.all(std > 0)
    summary = "\n".join(result.lines)
    assert "command error from the budget" in summary and "against the true surface's commands" in summary
    # the budget's command error and the one reached are of one size (the map's own error is
    # the budget's within a factor of a few on this coarse scan)
    predicted = float(summary.split("command error from the budget: RMS ")[1].split(" um")[0])
    actual = float(summary.split("against the true surface's commands: ")[1].split(" um")[0])
    assert 0.2 < actual / predicted < 5.0, summary
