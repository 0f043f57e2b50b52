"""One field on many processes: sphere points in blocks as Dask tasks (see docs/howto/dask.md).

- :func:`simulate`: a scene's wave-optics FieldMap on a cluster, resumable
  (:mod:`raysim.distributed.simulate`, partial store :mod:`raysim.distributed.partial`);
- :func:`block_runner` / :class:`BlockRunner`: any block job (the wave-aware inversion's
  forward model) evaluated on a cluster (:mod:`raysim.distributed.blocks`);
- :func:`connect`: the one way raysim reaches a Dask cluster, a scheduler address with
  timeouts and one-line errors or a local cluster (:mod:`raysim.distributed.cluster`);
- :mod:`raysim.distributed.process`: the set-up of a worker process for Warp work.

Layer: above :mod:`raysim.simulate`, below ``solver`` (whose wave forward model uses it).
"""

from raysim.distributed.blocks import BlockRunner, block_runner
from raysim.distributed.cluster import ClusterError, connect, scheduler_address
from raysim.distributed.simulate import simulate

__all__ = ["BlockRunner", "ClusterError", "block_runner", "connect", "scheduler_address", "simulate"]
