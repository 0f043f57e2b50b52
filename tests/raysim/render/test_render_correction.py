"""The report's correction section: drawn for a scene with panels (before / after, commands,
table), absent without panels, and the obstacle-blocked cells carried to the aperture."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from raysim.pipeline import report as report_module
from raysim.render.correction import blocked_on_aperture
from raysim.surface.deformation import Zernike
from tests.examples import equation_fieldmap, surfacemap

ROOT = Path(__file__).resolve().parents[3]
D, F = 110.0, 33.0
PANELS = """
[panels]
ring_edges_m = [0.0, 27.5, 55.0]
panels_per_ring = [6, 12]
gap_m = 0.01
"""


def _field(panels: bool):
    text = (ROOT / "scenes" / "paper_go.toml").read_text() + (PANELS if panels else "")
    truth = Zernike(((2, 2, 40e-6),), D / 2)
    return equation_fieldmap(truth, D, F, scene_name="t", scene=text), truth


def test_the_section_draws_maps_commands_and_a_row_per_actuator(tmp_path):
    field, truth = _field(panels=True)
    surface = surfacemap(truth, D, N=64, truth=truth, F=F, attrs={"solver": "example",
                                                                  "boundary": "test"})
    (tmp_path / "figures").mkdir()
    blocks = report_module.correction_section(field, surface, tmp_path)
    html = "".join(blocks)
    assert "<h2>Correction</h2>" in html and 'id="correction"' in html
    # 6 + 12 panels: 1 apex, 6 corners on r = 27.5 (12 with ring 2's cuts), 12 on the rim
    assert len(re.findall(r"<tr><td>corner-", html)) == 1 + 12 + 12
    assert "toward the focus" in html
    assert (tmp_path / "figures" / "correction.png").stat().st_size > 10_000


def test_a_map_no_actuator_could_follow_is_said_not_drawn(tmp_path):
    """raysim correct refuses a map departing by over 10 cm (a unit mistake); the report says
    so in its correction section and keeps the rest, instead of failing as a whole."""
    field, _ = _field(panels=True)
    wild = Zernike(((2, 2, 0.2),), D / 2)
    surface = surfacemap(wild, D, N=32, F=F, attrs={"solver": "example", "boundary": "test"})
    html = "".join(report_module.correction_section(field, surface, tmp_path))
    assert "<h2>Correction</h2><p>Not drawn: the map departs by up to" in html
    assert "is the deformation in metres?" in html and "<tr><td>corner-" not in html


def test_no_panels_no_section(tmp_path):
    field, truth = _field(panels=False)
    surface = surfacemap(truth, D, N=32, F=F, attrs={"solver": "example", "boundary": "test"})
    assert report_module.correction_section(field, surface, tmp_path) == []


def test_blocked_sphere_cells_mask_their_aperture_image():
    field, _ = _field(panels=True)
    _, phi = np.meshgrid(field["theta"].values, field["phi"].values, indexing="ij")
    # a leg's shadow: phi within 5 degrees of 90 degrees
    blocked = np.abs(phi - np.pi / 2) < np.radians(5)
    field["blocked"] = (("theta", "phi"), blocked.astype(np.uint8))
    x = np.linspace(-50, 50, 41)
    mask = blocked_on_aperture(field, x)
    X, Y = np.meshgrid(x, x)
    angle = np.degrees(np.arctan2(Y, X))
    assert mask[(np.abs(angle - 90) < 3) & (np.hypot(X, Y) > 5)].all()
    assert not mask[np.abs(angle - 90) > 8].any()
    assert blocked_on_aperture(_field(panels=False)[0], x) is None


def test_the_report_page_carries_the_section(tmp_path, monkeypatch):
    field, truth = _field(panels=True)
    surface = surfacemap(truth, D, N=48, truth=truth, F=F, attrs={"solver": "example",
                                                                  "boundary": "test"})
    monkeypatch.setattr(report_module, "_figures", lambda field, surface: [])
    page = report_module.write_report(field, surface, tmp_path).read_text()
    assert "<h2>Correction</h2>" in page and page.index("<h2>Correction</h2>") < page.index("<h2>Scene</h2>")
    assert (tmp_path / "figures" / "correction.png").is_file()
