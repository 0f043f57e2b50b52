"""The HTML pages in a real browser: Debian's headless Chromium (scripts/install-system-deps.sh).

For the ``report`` page, the ``check`` page and the documentation site's front page: every
image decodes (natural width > 0), nothing overflows a 1280 px window horizontally, and the
console stays free of errors (no exception, no failed resource). Skipped, with the reason,
where Chromium is absent; the site's page where the site has not been built (``make docs``,
which CI runs before the tests).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.browser import WIDTH, chromium, inspect, screenshot

ROOT = Path(__file__).resolve().parent.parent
SITE = ROOT / "docs" / "_build" / "html" / "index.html"

pytestmark = pytest.mark.skipif(chromium() is None,
                                reason="chromium is not installed (scripts/install-system-deps.sh)")

SCENE = """
name = "browser_check"
[dish]
diameter_m = 110.0
focal_length_m = 33.0
resolution_m = 1.5
[[deformation]]
type = "paper"
[source]
frequency_hz = 0.3e9
[sphere]
radius_m = 10.0
n_theta = 30
n_phi = 60
"""

SMALL_DISH = """
name = "small_dish"
[dish]
diameter_m = 10.0
focal_length_m = 3.0
resolution_m = 0.1
[source]
frequency_hz = 1e9
[sphere]
radius_m = 1.0
n_theta = 24
n_phi = 36
"""


def assert_reads_well(page: Path, min_images: int) -> None:
    report = inspect(page)
    assert report.console_errors == [] and report.exceptions == [], report
    assert report.failed_resources == [], report.failed_resources
    assert len(report.images) >= min_images, report.images
    broken = [img["src"] for img in report.images if not (img["complete"] and img["natural_width"] > 0)]
    assert broken == [], f"images that do not decode: {broken}"
    assert report.client_width == WIDTH
    assert report.scroll_width <= WIDTH, f"{page.name} is {report.scroll_width} px wide at {WIDTH} px"


def test_the_report_page(tmp_path):
    from raysim.pipeline.report import report

    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE)
    page = report(scene, tmp_path / "report", grid=32, refine=0)
    assert_reads_well(page, min_images=3)
    assert screenshot(page, tmp_path / "report.png").stat().st_size > 10_000


def test_the_check_page(tmp_path):
    from raysim.pipeline.check import write_check

    scene = tmp_path / "small.toml"
    scene.write_text(SMALL_DISH)
    page, _ = write_check(scene, tmp_path / "check", frequencies=[1e9], N=32, refine=0,
                          refine_model="none")
    assert_reads_well(page, min_images=2)


@pytest.mark.skipif(not SITE.exists(), reason="the site is not built here (make docs)")
def test_the_sites_front_page_and_a_tutorial(tmp_path):
    assert_reads_well(SITE, min_images=0)
    tutorial = SITE.parent / "tutorials" / "plot_4_pictures.html"
    assert_reads_well(tutorial, min_images=4)


def test_the_probe_sees_what_it_must(tmp_path):
    """The probe itself: a broken image, a console error and a too-wide page are caught."""
    page = tmp_path / "bad.html"
    page.write_text('<html><head><title>bad</title></head><body>'
                    '<img src="missing.png"><div style="width: 2000px">wide</div>'
                    '<script>console.error("boom")</script></body></html>')
    report = inspect(page)
    assert report.console_errors == ["boom"]
    assert report.failed_resources and report.failed_resources[0].endswith("missing.png")
    assert report.images[0]["natural_width"] == 0
    assert report.scroll_width >= 2000
