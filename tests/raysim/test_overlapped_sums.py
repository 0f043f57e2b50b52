"""simulate sums the ideal and the deformed reflector on two threads at once on the CPU: an
error or Ctrl-C on the main thread must not wait for the other thread's sum to end."""

from __future__ import annotations

import time

import numpy as np
import pytest
import warp as wp

import raysim
from raysim.optics import runtime
from raysim.optics import sources as sources_module


@wp.kernel
def _count(a: wp.array(dtype=wp.float64), offset: int):
    a[wp.tid() + offset] = a[wp.tid() + offset] + wp.float64(1.0)


def test_ctrl_c_while_the_second_reflector_starts_stops_the_first_ones_sum_at_its_next_launch(monkeypatch):
    """The first reflector's sum stands in as 2 000 launches 10 ms apart (20 s); Ctrl-C comes
    while the second reflector's elements are made. It reaches the caller within a second or
    two, and the first sum stopped at a launch instead of running on."""
    runtime.init()
    counts = wp.zeros(4, dtype=wp.float64, device="cpu")
    original, calls = sources_module.Sources.start, []

    def start(self, *args, **kwargs):
        calls.append(self)
        if len(calls) == 2:
            time.sleep(0.5)  # the first sum is under way
            raise KeyboardInterrupt("Ctrl-C while the deformed reflector starts")
        original(self, *args, **kwargs)

        def long_sum():
            for _ in range(2000):
                runtime.launch(_count, 4, [counts], "cpu")
                time.sleep(0.01)

        return long_sum

    monkeypatch.setattr(sources_module.Sources, "start", start)
    wave = raysim.load_scene("paper_po").with_overrides(0.1e9, 9, 36)
    begin = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        raysim.simulate(wave, method="po+ptd")
    assert time.perf_counter() - begin < 8.0  # the 20 s sum did not run to its end
    launched = counts.numpy()
    assert 0 < launched[0] < 1000 and np.all(launched == launched[0])


def test_blocks_evaluated_at_once_make_the_deformed_reflectors_sources_once(monkeypatch):
    """The deformed reflector's sources are made on first use (while the ideal's sum runs):
    two threads of one worker evaluating blocks of a fresh context make them once, and both
    get the bits of one evaluation after the other."""
    import threading

    from raysim import simulate

    scene = raysim.load_scene("paper_po").with_overrides(0.1e9, 6, 12)
    ideal, deformed = simulate.reflectors_for(scene)
    engine = simulate.BLOCK_ENGINES["po+ptd"]
    M = scene.sphere.n_theta * scene.sphere.n_phi
    reference, _ = engine.prepare(scene, ideal, deformed, simulate.Options(), "cpu", False).evaluate(0, M)
    original, made = sources_module.Sources.__init__, []

    def init(self, reflector, *args, **kwargs):
        if reflector is deformed:
            made.append(reflector)
            time.sleep(0.2)  # long enough for the other thread to ask for it too
        original(self, reflector, *args, **kwargs)

    monkeypatch.setattr(sources_module.Sources, "__init__", init)
    context = engine.prepare(scene, ideal, deformed, simulate.Options(), "cpu", False)
    outs: list = [None, None]

    def evaluate(i: int) -> None:
        outs[i] = context.evaluate(0, M)[0]

    threads = [threading.Thread(target=evaluate, args=(i,)) for i in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(made) == 1
    for out in outs:
        assert all(np.array_equal(out[name], reference[name]) for name in reference)
