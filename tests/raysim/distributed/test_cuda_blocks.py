"""Blocks on CUDA: the single-process CUDA FieldMap bit for bit, one local worker per GPU.

Skipped where no GPU is present (``scripts/device-check`` runs them where one is lent).
"""

from __future__ import annotations

import pytest

from raysim.distributed import connect
from raysim.distributed.blocks import block_bounds, run_blocks
from raysim.distributed.cluster import gpu_count
from raysim.distributed.simulate import scene_job
from raysim.distributed.simulate import simulate as simulate_blocks
from raysim.optics import runtime as warp_runtime
from raysim.scene.scene import parse_scene
from raysim.simulate import Options, simulate
from tests.raysim.distributed.conftest import SMALL, assert_same_fieldmap

pytestmark = [pytest.mark.gpu,
              pytest.mark.skipif(not warp_runtime.init().is_cuda_available(), reason="no CUDA GPU here")]


def test_cuda_blocks_give_the_single_process_cuda_fieldmap(inproc, tmp_path):
    scene = parse_scene(SMALL)
    single = simulate(scene, "po+ptd", "cuda", save_field=True)
    ds = simulate_blocks(scene, tmp_path / "f.nc", "po+ptd", "cuda", scheduler=inproc, block_size=64,
                         save_field=True)
    assert_same_fieldmap(single, ds)
    assert ds.attrs["blocks"] == 6 and ds.attrs["blocks_computed_twice"] == 0


def test_a_local_cluster_has_one_worker_per_gpu():
    scene = parse_scene(SMALL)
    job, _ = scene_job(scene, "po", Options(), "cuda", 1, 16)
    bounds = block_bounds(job.n_points, 16)
    seen = []
    with connect(device="cuda") as cluster:
        assert cluster.workers == gpu_count()
        run_blocks(cluster.client, job, range(len(bounds)), bounds, None, seen.append)
    devices = {meta["device"] for meta in seen}
    assert len(seen) == len(bounds) and devices <= {f"cuda:{i}" for i in range(gpu_count())}
    assert len(devices) == min(gpu_count(), len(bounds))
