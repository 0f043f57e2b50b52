"""``simulate`` on a Dask cluster: a scene's wave-optics FieldMap computed in blocks of sphere points.

The grid's points (flattened in C order over (theta, phi)) are cut into blocks of
``block_size`` points (a multiple of 4); each block is a Dask task that runs the method's block
engine (:data:`raysim.simulate.BLOCK_ENGINES`) on it. Workers rebuild the scene from its TOML
text (with the frequency and grid overrides), and with it the reflectors, quadratures, edges
and elements, once per process. Blocks go into the partial store ``OUTPUT.partial.zarr`` as
they finish (:mod:`raysim.distributed.partial`); ``resume=True`` completes the blocks a killed
client or worker left, and computes none twice. The FieldMap is written when every block is in,
then the partial store is removed. It is the single-process FieldMap bit for bit (data and
every attribute but the run's figures): the engines' per-point sums do not depend on the split,
and the finishing step is the single-process code on the same arrays.

Workers must import the same raysim and reach any file the scene names (a mesh) at the same
path; the partial store is written by the workers where they see it (a shared file system),
else by the client from the blocks they return.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import xarray as xr

from raysim.distributed.blocks import block_bounds, block_size_for, run_blocks
from raysim.distributed.cluster import ClusterError, connect
from raysim.distributed.inputs import changed_inputs, input_digests
from raysim.distributed.partial import PartialStore, partial_path
from raysim.optics.fast import DEFAULT_TOL
from raysim.progress import Progress
from raysim.scene import Scene
from raysim.scene.scene import parse_scene
from raysim.simulate import BLOCK_ENGINES, BlockContext, Options, check_method, fieldmap_of, with_blockage
from raysim.surface.mesh import reflectors_for
from raysim.version import __version__

FORMAT = 1
#: FieldMap attributes that describe a run rather than its result (they differ between runs)
RUN_ATTRS = ("created", "seconds_mesh", "seconds_total", "seconds_edges", "pair_rate", "workers",
             "scheduler", "blocks", "block_size", "blocks_reused", "blocks_computed", "blocks_repaired",
             "blocks_computed_twice", "block_element_sets", "seconds_blocks", "seconds_blocks_cpu",
             "seconds_context", "seconds_context_total")



@dataclass(frozen=True)
class SceneJob:
    """A scene's simulation as a job of :mod:`raysim.distributed.blocks`."""

    key: str
    text: str
    source: str
    base: str
    frequency_hz: float
    n_theta: int
    n_phi: int
    method: str
    options: Options
    device: str
    threads: int
    block_size: int
    inputs: tuple[tuple[str, str], ...] = ()  # (file the scene names, its SHA-256) at submission

    @property
    def n_points(self) -> int:
        return self.n_theta * self.n_phi

    def parts(self) -> dict[str, tuple[int, ...]]:
        return BLOCK_ENGINES[self.method].parts(self.options)

    def scene(self) -> Scene:
        base = Path(self.base)
        return parse_scene(self.text, self.source, base).with_overrides(self.frequency_hz, self.n_theta,
                                                                        self.n_phi)

    def build(self, device: str, keep: bool) -> BlockContext:
        scene = self.scene()
        # a file edited after the run began would give blocks of another version of it
        changed = changed_inputs(dict(self.inputs), input_digests(scene.files, self.base))
        if changed:
            raise ClusterError(f"{changed[0]}, a file the scene names, changed after the run began "
                               "(its SHA-256 differs): restore it, then resume")
        ideal, deformed = reflectors_for(scene)
        return BLOCK_ENGINES[self.method].prepare(scene, ideal, deformed, self.options, device, keep)


def scene_job(scene: Scene, method: str, options: Options, device: str, threads: int,
              block_size: int) -> tuple[SceneJob, dict[str, str]]:
    """The job of ``scene`` and what its fingerprint is made of (for messages)."""
    import warp

    base = str(scene.path.resolve().parent) if scene.path is not None else str(Path.cwd())
    source = str(scene.path) if scene.path is not None else "scene"
    sphere = scene.sphere
    made = {"format": FORMAT, "scene": scene.text, "base": base,
            "frequency_hz": repr(scene.source.frequency_hz), "grid": f"{sphere.n_theta}x{sphere.n_phi}",
            "method": method,
            "options": json.dumps(asdict(options), sort_keys=True), "device": device,
            "block_size": str(block_size), "versions": f"raysim {__version__}, warp {warp.__version__}"}
    # the text names its maps, panel tables and meshes; their bytes decide the blocks too, so a
    # resume after one was edited is refused (naming it) instead of merging blocks of both
    inputs = input_digests(scene.files, base)
    made.update({f"file {name}": digest for name, digest in inputs.items()})
    key = hashlib.sha256(json.dumps(made, sort_keys=True).encode()).hexdigest()
    description = {k: (hashlib.sha256(v.encode()).hexdigest()[:12] if k == "scene"
                       else v[:12] if k.startswith("file ") else str(v))
                   for k, v in made.items()}
    job = SceneJob(key, scene.text, source, base, float(scene.source.frequency_hz), sphere.n_theta,
                   sphere.n_phi, method, options, device, int(threads), int(block_size),
                   tuple(inputs.items()))
    _check_rebuilds(scene, job)
    return job, description


def _check_rebuilds(scene: Scene, job: SceneJob) -> None:
    """Workers rebuild the scene from its text: refuse a scene changed in Python since."""
    try:
        again = job.scene()
    except Exception as exc:
        raise ClusterError(f"the scene cannot be rebuilt from its text on the workers ({exc})") from exc
    same = (_resolved(again.dish) == _resolved(scene.dish) and again.source == scene.source
            and again.sphere == scene.sphere
            and again.subdivisions == scene.subdivisions and repr(again.panels) == repr(scene.panels)
            and again.deformation.describe() == scene.deformation.describe()
            and _resolved_obstacles(again.obstacles) == _resolved_obstacles(scene.obstacles))
    if not same:
        raise ClusterError("the scene differs from its TOML text (changed in Python?): workers rebuild "
                           "it from the text, with only the frequency and grid overridden")


def _absolute(path: Path | None) -> Path | None:
    return None if path is None else Path(path).resolve()


def _resolved(dish):
    """The dish with its files' paths absolute: the workers' scene resolves them against the
    scene's folder made absolute, a scene read as ``scene.toml`` against ``.`` (a mesh scene
    run from its own folder was refused as changed in Python)."""
    return replace(dish, mesh=_absolute(dish.mesh), ideal_mesh=_absolute(dish.ideal_mesh))


def _resolved_obstacles(obstacles: tuple) -> tuple:
    """The obstacles with their mesh files' paths absolute (as :func:`_resolved`)."""
    return tuple(replace(o, path=_absolute(o.path)) if hasattr(o, "path") else o for o in obstacles)


def simulate(scene: Scene, output: str | Path, method: str | None = None, device: str = "cpu",
             progress: Progress | None = None, *, scheduler: str | None = None,
             workers: int | None = None, threads: int = 1, resume: bool = False,
             block_size: int | None = None, total: bool = False, save_field: bool = False,
             samples_per_wavelength: float | None = None, edges: str | None = None,
             radiator: str = "fast", radiator_tol: float = DEFAULT_TOL) -> xr.Dataset:
    """Simulate ``scene`` on Dask and write its FieldMap to ``output``; return the FieldMap.

    Options as :func:`raysim.simulate.simulate`, and: ``scheduler`` (address of a running Dask
    scheduler) or ``workers`` (local worker processes; default one per core, one per GPU for
    cuda); ``threads`` (CPU threads of each Warp launch in a worker); ``resume`` (complete the
    partial store an interrupted run left; without it an existing one is refused);
    ``block_size`` (points per block, a multiple of 4; default 1024 on the CPU, 32768 on CUDA);
    a resume first verifies every finished block against its checksums and computes again the
    ones that fail (``blocks_repaired`` in the FieldMap's attributes);
    ``progress(stage, fraction)`` over blocks (:mod:`raysim.progress`; the stage reads
    ``N of M blocks``).
    """
    start = time.perf_counter()
    options = Options(total, save_field, samples_per_wavelength, edges, False, radiator, radiator_tol)
    method = check_method(scene, method, options, device)
    if method not in BLOCK_ENGINES:
        raise ClusterError(f"--scheduler and --workers apply to the wave methods "
                           f"({', '.join(BLOCK_ENGINES)}); {method} runs in one process")
    if threads < 1:
        raise ClusterError(f"threads must be >= 1, got {threads}")
    if scheduler is None and device != "cpu":  # local workers see this machine's devices
        from raysim.optics import runtime

        runtime.resolve_device(device)
    n_points = scene.sphere.n_theta * scene.sphere.n_phi
    size = block_size_for(n_points, device, block_size)
    job, description = scene_job(scene, method, options, device, threads, size)
    path = partial_path(output)
    created = not path.exists()
    store = _partial(path, job, description, resume)
    repaired = [] if created else store.verify()
    if not created and store.context() is None and store.markers():
        # the context's attributes come with every computed block: one block computed again
        # brings back a context.json that was lost or torn
        (store.path / "context.json").unlink(missing_ok=True)
        repaired = repaired or [min(store.markers())]
    for index in repaired:  # a block whose data cannot be trusted is computed again
        store.reset(index)
    bounds = block_bounds(n_points, size)
    run = _Run(len(bounds), len(store.markers()), progress)
    pending = [i for i in range(len(bounds)) if store.marker(i) is None]
    cluster_workers, address = 0, "none"
    try:
        if pending:
            with connect(scheduler, workers=workers, threads=threads, device=device,
                         tasks=len(pending)) as cluster:
                cluster_workers, address = cluster.workers, cluster.address
                run_blocks(cluster.client, job, pending, bounds, store, run.block)
    except BaseException:
        if created and not store.markers():  # nothing to resume: leave nothing behind
            store.remove()
        raise
    ds = _fieldmap(scene, method, options, store, device)
    ds.attrs.update({"seconds_total": time.perf_counter() - start, "workers": cluster_workers,
                     "scheduler": address, "blocks_reused": run.reused,
                     "blocks_computed": run.computed, "blocks_repaired": len(repaired)})
    from raysim.maps.fieldmap import save

    save(ds, output)
    store.remove()
    return ds


class _Run:
    """Counts blocks as they come in and reports them."""

    def __init__(self, n_blocks: int, reused: int, progress: Progress | None) -> None:
        self.n_blocks, self.reused, self.computed, self.skipped = n_blocks, reused, 0, 0
        self.progress = progress
        self.report(reused)

    def report(self, done: int) -> None:
        if self.progress is not None:
            self.progress(f"{done} of {self.n_blocks} blocks", done / self.n_blocks if self.n_blocks else 1.0)

    def block(self, meta: dict) -> None:
        if meta.get("skipped"):
            self.skipped += 1
        else:
            self.computed += 1
        self.report(self.reused + self.computed + self.skipped)


def _partial(path: Path, job: SceneJob, description: dict[str, str], resume: bool) -> PartialStore:
    """The run's partial store: opened to resume, else new (an existing one is refused)."""
    if path.exists():
        if not resume:
            raise ClusterError(f"{path} holds blocks of an interrupted run: add --resume to complete "
                               "it, or delete it to start again")
        return PartialStore.open(path, job.key, description)
    path.parent.mkdir(parents=True, exist_ok=True)
    return PartialStore.create(path, job.key, description, job.parts(), job.n_points, job.block_size)


def _fieldmap(scene: Scene, method: str, options: Options, store: PartialStore, device: str) -> xr.Dataset:
    """The FieldMap from a complete partial store (the single-process finishing step)."""
    records = store.markers()
    missing = [i for i in range(store.n_blocks) if i not in records]
    context = store.context()
    if missing or context is None:
        raise ClusterError(f"{store.path}: {len(missing)} blocks missing after the run (first {missing[:1]})")
    figures: dict[str, float] = {}
    for index in range(store.n_blocks):  # summed in block order: the same total whatever came first
        for key, value in records[index]["figures"].items():
            figures[key] = figures.get(key, 0.0) + value
    engine = BLOCK_ENGINES[method]
    run = engine.finish(scene, options, context, store.read(), figures)
    if scene.obstacles:
        run = with_blockage(reflectors_for(scene)[0], run, scene.sphere, scene.source.direction, device)
    counts = np.array([records[i]["count"] for i in range(store.n_blocks)])
    build = [records[i]["build_seconds"] for i in range(store.n_blocks)]
    attrs = {**context["mesh"], **run.attrs, "device": str(device),
             "seconds_context": float(max(build)), "seconds_context_total": float(sum(build)),
             "seconds_blocks": float(sum(r["wall"] for r in records.values())),
             "seconds_blocks_cpu": float(sum(r.get("cpu", np.nan) for r in records.values())),
             "blocks": store.n_blocks, "block_size": store.block_size,
             "blocks_computed_twice": int(np.sum(counts > 1)),
             "block_element_sets": len({r["digest"] for r in records.values()})}
    return fieldmap_of(scene, method, run, context["focal_length"], context["diameter"], attrs)
