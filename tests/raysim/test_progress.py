"""The one progress protocol: sub-ranges and monotone fractions compose as documented."""

from __future__ import annotations

import pytest

from raysim.progress import monotone, silent, within


def test_within_maps_a_sub_step_onto_its_slice_and_clips():
    calls = []
    sub = within(lambda stage, fraction: calls.append((stage, fraction)), 0.25, 0.75, "ideal")
    for f in (-0.5, 0.0, 0.5, 1.0, 2.0):
        sub("rays", f)
    assert [s for s, _ in calls] == ["ideal: rays"] * 5
    assert [f for _, f in calls] == pytest.approx([0.25, 0.25, 0.5, 0.75, 0.75])
    assert within(None, 0.0, 1.0) is silent  # no parent: nothing to report


def test_monotone_never_goes_back():
    seen = []
    report = monotone(lambda stage, fraction: seen.append(fraction))
    for f in (0.1, 0.4, 0.2, 0.9, 0.5, 1.0):
        report("x", f)
    assert seen == [0.1, 0.4, 0.4, 0.9, 0.9, 1.0]


def test_scan_steps_report_through_the_same_shape():
    """A scan's steps reach fraction 1 with a readable stage (hardware.acquire)."""
    from hardware.acquire import step_progress

    seen = []
    for done in range(4):
        step_progress(lambda stage, fraction: seen.append((stage, fraction)), done, 3)
    assert seen[-1] == ("step 3 of 3", 1.0) and seen[0] == ("step 0 of 3", 0.0)
