"""The wave refinement's forward model in blocks on Dask: the same fields and SurfaceMap."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from raysim.cli import main
from raysim.distributed import block_runner
from raysim.distributed import blocks as dblocks
from raysim.maps.fieldmap import save
from raysim.maps.sphere import SphereGrid
from raysim.scene.scene import parse_scene
from raysim.simulate import simulate
from raysim.surface.deformation import GaussianBumps
from solver import forward, surface
from solver.aperture import ApertureGrid
from tests.raysim.distributed.conftest import SMALL

D, F, FREQUENCY = 10.0, 4.0, 1.0e9


def test_the_wave_model_in_blocks_is_the_wave_model(inproc):
    """PO + PTD, total field: the ideal and a deformed field, in 7 blocks, bit for bit."""
    sphere = SphereGrid(2.0, 9, 24)
    grid = ApertureGrid(D, 32)
    X, Y = grid.XY
    delta = GaussianBumps(((1.0, -0.5, 2e-3, 1.5),))(X, Y)
    def model():  # a fresh model each time: it keeps its ideal field for its life
        return forward.WaveForward(FREQUENCY, polarization=0.3, total=True, ptd=True)

    here = model()
    plain = here.ideal_field(sphere, F, D), here(sphere, F, D, grid.x, grid.y, delta)
    model = model()
    with block_runner(inproc, block_size=32) as runner, forward.distributed(runner):
        blocks = model.ideal_field(sphere, F, D), model(sphere, F, D, grid.x, grid.y, delta)
        assert runner.blocks == 2 * 7
    assert np.array_equal(plain[0], blocks[0]) and np.array_equal(plain[1], blocks[1])
    assert not np.array_equal(np.sum(np.abs(plain[0]) ** 2, axis=-1), plain[1])  # the bump shows


def test_invert_with_a_scheduler_writes_the_same_surface(inproc, tmp_path, monkeypatch, capsys):
    scene = parse_scene(SMALL).with_overrides(n_theta=18, n_phi=24)
    path = save(simulate(scene, "po"), tmp_path / "po.nc")

    def run(name: str, *extra: str):
        monkeypatch.setattr(sys, "argv", ["raysim", "invert", str(path), "-o", str(tmp_path / name),
                                          "--grid", "32", "--refine", "1", "--model", "po",
                                          "--refine-method", "defect", *extra])  # auto would differ:
        # Gauss-Newton in process, the defect correction alone with a scheduler
        with pytest.raises(SystemExit) as exit_info:
            main()
        assert exit_info.value.code in (0, None), capsys.readouterr().err
        return surface.load(tmp_path / name)

    here = run("here.nc")
    calls = []
    real = dblocks.run_blocks
    monkeypatch.setattr(dblocks, "run_blocks", lambda *a, **k: calls.append(1) or real(*a, **k))
    there = run("there.nc", "--scheduler", inproc)
    assert there.attrs["refine_model"] == "po" and len(calls) >= 2  # the ideal field, one update
    assert np.array_equal(here["deformation"].values, there["deformation"].values, equal_nan=True)
