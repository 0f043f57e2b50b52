"""The fast radiator: :class:`raysim.optics.radiator.Radiator`'s interface, summed multilevel.

Elements added under a kind are kept (sources change nothing until a field is read); the first
:meth:`FastRadiator.sums_of` of a kind plans a tree (:mod:`raysim.optics.fast.multilevel`),
compares its estimated cost with the direct sum's and runs the cheaper; ``method`` records
which ran per kind. Targets that are not on one sphere about ``centre`` always take the direct
sum. ``pairs`` counts the element-point pairs the
direct sum would have evaluated, so ``rate()`` is an equivalent rate.

A kind whose kept elements reach :data:`BATCH_BYTES` is summed there and then, on a tree of its
own, and its elements let go; the sums of the batches add (the sum is linear in the elements).
So however many elements a reflector has, at most a batch of them is held: at 12 GHz on the
paper's dish they are 8 GB, four batches of 2 GB.
"""

from __future__ import annotations

import hashlib
import math
import numbers
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.errors import RaysimError
from raysim.optics.fast import DEFAULT_TOL, multilevel
from raysim.optics.fast.chart import OVERSAMPLINGS, Domain, domain_of, stencil_for, to_angles
from raysim.optics.radiator import Radiator, field_of
from raysim.progress import Progress

#: kinds the multilevel sum serves: point elements. go+edge's diffraction elements integrate
#: along edge segments metres long (their field is not that of a point at their position), so
#: they always take the direct sum
FAST_KINDS = ("electric", "magnetic", "fringe", "shift")
#: the finest tolerance asked for that the sums can honour: the direct sum itself, float64 over
#: up to ~1e8 elements, carries rounding of about this order (the error-against-tolerance curve
#: of docs/engines.md reaches 5e-11 at 1e-8); finer ones only make the grids grow
MIN_TOL = 1e-12
RADIATORS = ("fast", "direct")
#: the sum's interpolation steps at most (the tree's levels in practice, plus the last step)
STEPS = 8
#: elements of a kind kept at most (bytes) before they are summed as one batch (each batch its own
#: tree): 2 GiB is the paper's dish at 6 GHz in one batch (2.07 GB), so batches only begin above
#: it, and a batch's planning and walk peak where that run did (4.8 GB; 5.7 GB for the whole
#: 12 GHz run, with every batch's tree kept)
BATCH_BYTES = 2 << 30


def tol_problem(tol: object, name: str = "radiator tolerance") -> str | None:
    """Why ``tol`` is not a radiator tolerance (a real number in [MIN_TOL, 1)); None when it is."""
    if isinstance(tol, numbers.Real) and not isinstance(tol, bool) and math.isfinite(tol) \
            and MIN_TOL <= tol < 1:
        return None
    return f"{name} must lie in [{MIN_TOL:g}, 1), got {tol!r}"


def _segments(kind: str) -> Any:
    from raysim.optics.kernels import goedge, po, po_derivative, ptd

    return {"electric": po.segments_electric, "magnetic": po.segments_magnetic,
            "fringe": ptd.segments_fringe, "diffraction": goedge.segments_diffraction,
            "shift": po_derivative.segments_shift}[kind]


class FastRadiator:
    """The field (V/m) of current elements at points on a sphere, by the multilevel sum.

    Parameters
    ----------
    points : (n, 3) field points (m, reflector frame).
    k : wavenumber (rad/m).
    device : Warp device.
    tol : the relative accuracy sought (interpolation error per step is set from it).
    centre : (3,) m, the centre of the targets' sphere (the focus); None: direct sum only.
    domain : the whole job's :class:`Domain` (a block of a grid passes the grid's, so the
        field is bit-identical whatever the split); default: the points' own.
    force : run the multilevel sum even where the direct sum is estimated cheaper (tests).
    cache : a dict kept by the owner of the elements (:class:`raysim.optics.sources.Sources`):
        the plan, the sums on a tensor grid and (when they fit one chunk) the stop level's grids
        are stored there per kind, domain and tolerance, so later blocks of points only look up
        or interpolate (the elements of a kind must not change between uses).
    plans : a dict shared between radiators of the same elements moved (a central
        difference's two copies; the ideal and the deformed reflector of one triangulation):
        the first plans each kind's tree and keeps it there, the others sum on that tree
        while its grids still hold their clusters (:func:`raysim.optics.fast.multilevel.holds`),
        and skip planning. One tree makes the sums one linear map of the elements' exact leaf
        fields, so the approximation errors of two copies cancel in their difference instead
        of adding to it. Batches are keyed by their number, so batch i of one copy sums on
        batch i's tree of the other.
    batch_bytes : the elements of a kind kept at most before they are summed as a batch
        (default :data:`BATCH_BYTES`); a batch ends at the first added piece that reaches it,
        so the batches depend only on the pieces added, not on the points.
    """

    def __init__(self, points: ArrayLike, k: float, device: str | None = "cpu", block: int | None = None,
                 tol: float = DEFAULT_TOL, centre: ArrayLike | None = None, domain: Domain | None = None,
                 force: bool = False, cache: dict | None = None, plans: dict | None = None,
                 batch_bytes: int | None = None) -> None:
        if (problem := tol_problem(tol)) is not None:
            raise RaysimError(problem)
        self.direct = Radiator(points, k, device, block=block)
        self.device = self.direct.device
        self.points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        self.n = self.direct.n
        self.k = float(k)
        self.tol = float(tol)
        self.force = force
        self.cache = cache
        self.plans = plans
        self.domain = domain
        self.angles: NDArray[np.float64] | None = None
        if centre is not None and self.n:
            own = domain_of(self.points, centre)
            if own is not None and domain is None:
                self.domain = own
            if own is None or not _same_sphere(own, self.domain):
                self.domain = None
            if self.domain is not None:
                self.angles = to_angles(self.points, self.domain.centre)
        elif centre is None:
            self.domain = None
        self.batch_bytes = BATCH_BYTES if batch_bytes is None else batch_bytes
        if not self.batch_bytes > 0:
            raise RaysimError(f"batch size must be > 0 bytes, got {batch_bytes!r}")
        self.sources: dict[str, list[NDArray[np.float64]]] = {}
        self.leaf_order: dict[str, multilevel.Plan] = {}  # kinds held as one array in a plan's leaf order
        self.results: dict[str, NDArray[np.float64]] = {}
        self.batches: dict[str, int] = {}  # batches of a kind summed and let go
        self.summed: dict[str, NDArray[np.float64]] = {}  # their sums, added up
        self.method: dict[str, str] = {}
        self.planned: dict[str, multilevel.Plan | None] = {}  # each kind's tree for the elements kept
        self.keys: dict[str, tuple] = {}  # and their key in ``cache``
        self.pairs = 0
        self.seconds = 0.0

    def add_packed(self, src: Any, kind: str = "electric", progress: Progress | None = None,
                   extent: Any = None) -> None:
        """Keep elements of ``kind`` (numpy or Warp float64, the kernels' packed layout), by
        reference where they are float64 on the CPU (at 6 GHz on the paper's dish a copy is
        2 GB): the caller does not change them afterwards."""
        spec = self.direct.kinds[kind]
        a = src.numpy() if hasattr(src, "numpy") else np.asarray(src, dtype=np.float64)
        if a.shape[0] != spec.rows:
            raise RaysimError(f"{kind} elements have {spec.rows} rows, got {a.shape[0]}")
        if a.shape[1] == 0 or self.n == 0:
            return
        self.direct._check_phase((a[:3].min(axis=1), a[:3].max(axis=1)))
        self.sources.setdefault(kind, []).append(np.asarray(a, dtype=np.float64))
        self.leaf_order.pop(kind, None)
        self.planned.pop(kind, None)
        self.keys.pop(kind, None)
        self.results.pop(kind, None)
        self.pairs += a.shape[1] * self.n
        if self._batched(kind) and sum(part.nbytes for part in self.sources[kind]) >= self.batch_bytes:
            self._sum_batch(kind)
        if progress is not None:
            progress("elements kept", 1.0)

    def _batched(self, kind: str) -> bool:
        """Whether ``kind`` is summed in batches here: the multilevel sum could take it."""
        return self.domain is not None and self.angles is not None and kind in FAST_KINDS

    def _sum_batch(self, kind: str) -> None:
        """Sum the kept elements of ``kind`` as one batch, add that to the batches' sums and let
        the elements go."""
        start = time.perf_counter()
        sums = self._run(kind)
        self.summed[kind] = sums if kind not in self.summed else self.summed[kind] + sums
        self.batches[kind] = self.batches.get(kind, 0) + 1
        self.sources[kind] = []
        self.leaf_order.pop(kind, None)
        self.planned.pop(kind, None)
        self.keys.pop(kind, None)
        self.seconds += time.perf_counter() - start

    def add(self, elements: Any, progress: Progress | None = None) -> None:
        if len(elements):
            self.add_packed(elements.packed(), elements.kind, progress)

    def rate(self) -> float:
        """Equivalent pairs (element x field point) per second so far."""
        return self.pairs / self.seconds if self.seconds > 0 else 0.0

    def sums_of(self, kind: str) -> NDArray[np.float64]:
        """The raw sums (n, 6) of ``kind`` at the points, as :meth:`Radiator.sums_of`: those of
        the batches already summed plus those of the elements kept."""
        if kind not in self.sources:
            return np.zeros((self.n, 6))
        if kind not in self.results:
            start = time.perf_counter()
            kept = bool(self.sources[kind])
            # method[kind] names the last sum run: of the elements kept, else of the last batch
            sums = self._run(kind) if kept else np.zeros((self.n, 6))
            if kind in self.summed:
                sums = sums + self.summed[kind]
                self.method[kind] = f"{self.method[kind]}, {self.batches[kind] + kept} batches"
            self.results[kind] = sums
            self.seconds += time.perf_counter() - start
        return self.results[kind]

    def _key(self, kind: str) -> tuple:
        """The ``cache``'s key of the elements of ``kind`` kept: the kept grids belong to these
        very elements, so it holds their bytes' digest, not their count."""
        if kind not in self.keys:
            digest = hashlib.blake2b(digest_size=16)
            for part in self.sources[kind]:
                digest.update(np.ascontiguousarray(part).data)  # no copy
            self.keys[kind] = (kind, self.domain, self.tol, digest.digest())
        return self.keys[kind]

    def _run(self, kind: str) -> NDArray[np.float64]:
        key = self._key(kind)
        if self.cache is not None and key in self.cache:
            the_plan, store = self.cache[key]
            self.method[kind] = describe(the_plan)
            return multilevel.to_targets(self._grids(kind, the_plan, store), the_plan, self.angles,
                                         self.points, self.k, self.device, self.domain, store)
        the_plan = self._plan(kind)
        if the_plan is None or (the_plan.cost >= the_plan.direct_cost and not self.force):
            self.method[kind] = "direct"
            one = Radiator(self.points, self.k, self.device, block=self.direct.block)
            for part in self.sources[kind]:
                one.add_packed(part, kind)
            return one.sums_of(kind)
        self.method[kind] = describe(the_plan)
        assert self.domain is not None and self.angles is not None
        store: dict = {}
        if self.cache is not None:
            self.cache[key] = (the_plan, store)
        return multilevel.to_targets(self._grids(kind, the_plan, store), the_plan, self.angles,
                                     self.points, self.k, self.device, self.domain, store)

    def _plan(self, kind: str) -> multilevel.Plan | None:
        """The tree of the elements of ``kind`` kept (None: the direct sum serves them), planned
        once for them: another radiator's from ``plans`` where it holds them, else a new one,
        shared there."""
        if kind in self.planned:
            return self.planned[kind]
        the_plan = None
        if self.domain is not None and self.angles is not None and kind in FAST_KINDS:
            # the tree is planned on the pieces as they were added, without an (n, 3) copy of
            # their positions: at high frequency the planning, not the walk, sets the peak
            # memory (at 12 GHz on the paper's dish the elements are 8 GB, an (n, 3) array
            # 2.7 GB); the leaf order then empties this list, freeing the pieces one by one
            pieces = self.sources[kind]
            tree = (kind, self.domain, self.tol, self.batches.get(kind, 0))
            shared = None if self.plans is None else self.plans.get(tree)
            if shared is not None and multilevel.holds(shared, pieces, self.domain, self.k):
                the_plan = shared
            else:
                the_plan = plan_for(pieces, self.domain, self.k, self.tol, kind=kind)
                if self.plans is not None and the_plan is not None:
                    self.plans[tree] = the_plan
        self.planned[kind] = the_plan
        return the_plan

    def prepare(self) -> None:
        """Plan every kept kind's tree now (sharing it through ``plans``) and load the kernels
        the sums will launch, without summing. Radiators that share ``plans`` prepared one
        after another in a fixed order may then sum at once on separate threads: which tree
        each one sums on, and so every bit of its sums, is what summing them in that order
        would give."""
        from raysim.optics import runtime
        from raysim.optics.kernels import fast

        wp = runtime.init()
        for kind, pieces in self.sources.items():
            if not pieces or kind in self.results:
                continue
            if self.cache is not None and self._key(kind) in self.cache:
                continue  # summed before: its grids or sums are kept
            if self._plan(kind) is not None:
                for kernel in (*_segments(kind), fast.rephase_merge):
                    wp.load_module(kernel.module, device=self.device)

    def _in_leaf_order(self, kind: str, the_plan: multilevel.Plan) -> NDArray[np.float64]:
        """The kind's elements as one array in ``the_plan``'s leaf order, held in place of the
        pieces they were added in (one copy of the elements, not two: at 6 GHz on the paper's
        dish each is 2 GB; the sums do not depend on the elements' order)."""
        if self.leaf_order.get(kind) is not the_plan:
            self.sources[kind] = [multilevel.leaf_ordered(self.sources.pop(kind), the_plan)]
            self.leaf_order[kind] = the_plan
        return self.sources[kind][0]

    def _grids(self, kind: str, the_plan: multilevel.Plan,
               store: dict) -> Callable[[], Iterator[tuple[int, int, NDArray[np.complex128]]]]:
        """The stop grids' chunks, as :func:`raysim.optics.fast.multilevel.to_targets` reads
        them: kept in ``store`` for later blocks of points when they come in one chunk (one
        chunk's memory) and the last step interpolates them; summed again from the elements
        otherwise (a tensor plan keeps its grid's sums instead)."""
        assert self.domain is not None
        domain = self.domain

        def grids() -> Iterator[tuple[int, int, NDArray[np.complex128]]]:
            if "stop" in store:
                yield from store["stop"]
                return
            ordered = self._in_leaf_order(kind, the_plan)
            chunks = multilevel.stop_grids(_segments(kind), ordered, the_plan, domain, self.k, self.device)
            if the_plan.oversampling and len(the_plan.stop_chunks()) == 1:
                store["stop"] = list(chunks)
                yield from store["stop"]
            else:
                yield from chunks

        return grids

    def field(self, kinds: tuple[str, ...] | None = None) -> NDArray[np.complex128]:
        """E (n, 3) complex (V/m) of everything added so far (or of the ``kinds`` named)."""
        chosen = [kind for kind in self.sources if kinds is None or kind in kinds]
        if not chosen:
            return np.zeros((self.n, 3), dtype=np.complex128)
        return field_of({kind: self.sums_of(kind) for kind in chosen}, self.k)


def plan_for(pieces: Sequence[NDArray[np.float64]], domain: Domain, k: float, tol: float,
             count: int | None = None, kind: str = "electric") -> multilevel.Plan | None:
    """The multilevel plan for relative accuracy ``tol`` of the elements of ``pieces`` ((rows,
    n_i) arrays whose rows 0..2 are the positions, m: a kind's packed elements, or
    ``positions.T``): each of the sum's interpolation steps (one per level and the last) is
    held to a share of it, tol / sqrt(:data:`STEPS`), and the last step's stencil to a quarter.
    The steps' errors are those of different grids (each level's truncated spectrum, re-phased
    onto another centre), uncorrelated, so they add as a root sum of squares, not linearly; the
    grids' rule bounds the worst cluster in its worst direction, and the field's error,
    measured against the direct sum, stays under ``tol``: 7 to 80 times under on the paper's
    dish from 0.1 to 12 GHz, 2.3 times at the least measured (the Jacobian's sums to scattered
    points on a sphere of 0.6 F; docs/engines.md).
    ``kind``: whose pair function the leaf step runs (its cost weighs the leaves against the
    levels above; a transposed sum plans as the kind it transposes)."""
    last = tuple((u, stencil_for(tol / 4.0, u)) for u in OVERSAMPLINGS)
    pair_cost = multilevel.PAIR_COST.get(kind, multilevel.SCALAR_PAIR_COST)
    return multilevel.plan(pieces, domain, k, tol / math.sqrt(STEPS), last, count=count, pair_cost=pair_cost)


def describe(the_plan: multilevel.Plan) -> str:
    """One line naming the plan's levels, grid sizes and last step (FieldMap ``radiator_ran``)."""
    sizes = f"{the_plan.sizes[the_plan.stop]}..{the_plan.sizes[the_plan.leaf]}"
    own = the_plan.leaf_sizes
    if own is not None and the_plan.stop < the_plan.leaf and own.min() < own.max():
        sizes += f" (leaves {own.min()}..{own.max()})"  # each leaf on a grid of its own size
    last = "series on the grid" if the_plan.oversampling == 0 else \
        f"x{the_plan.oversampling} p {the_plan.p}"
    return f"fast (levels {the_plan.stop}..{the_plan.leaf}, grids {sizes}, last {last})"


def _same_sphere(own: Domain, domain: Domain | None) -> bool:
    """Whether the points' own domain lies on ``domain``'s sphere."""
    if domain is None:
        return False
    return bool(np.allclose(own.centre, domain.centre, rtol=0, atol=1e-9 * domain.radius)
                and abs(own.radius - domain.radius) <= 1e-9 * domain.radius)


def estimated_cost(positions: ArrayLike, points: ArrayLike, k: float, centre: ArrayLike,
                   tol: float = DEFAULT_TOL, count: int | None = None) -> tuple[float, float]:
    """(cost, direct): what summing point elements at ``positions`` (n, 3) m to ``points``
    (m, 3) m costs the fast radiator (the cheaper of its multilevel plan and the direct sum, as
    :class:`FastRadiator` chooses) and the direct sum, both in direct pair evaluations.
    ``centre``: the targets' sphere centre (m); ``k`` rad/m; ``count``: the number of elements
    when ``positions`` are an even subset of them. Plans only: nothing is summed."""
    pos = np.ascontiguousarray(np.asarray(positions, dtype=np.float64).reshape(-1, 3))
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = len(pos) if count is None else int(count)
    direct = float(n) * len(pts)
    domain = domain_of(pts, centre)
    if domain is None or len(pos) == 0:
        return direct, direct
    the_plan = plan_for([pos.T], domain, k, tol, count=n)
    return (direct if the_plan is None else min(the_plan.cost, direct)), direct


#: sample positions at most that plan a cost estimate's tree (an even subset of them)
PLAN_SUBSET = 1 << 21


def quadrature_cost(quadrature: Any, points: ArrayLike, k: float, centre: ArrayLike,
                    radiator: str = "fast", tol: float = DEFAULT_TOL) -> tuple[float, float]:
    """(cost, direct) of radiating every sample of ``quadrature`` (a
    :class:`raysim.surface.quadrature.FaceQuadrature`) to ``points`` (m, 3) m, as ``radiator``
    would run it and as the direct sum would, in direct pair evaluations. The fast radiator's
    plan is made on an even subset of at most :data:`PLAN_SUBSET` sample positions, its costs
    counted for all of them; nothing is summed."""
    n = quadrature.n_samples
    direct = float(n) * len(np.asarray(points).reshape(-1, 3))
    if radiator == "direct" or n == 0:
        return direct, direct
    stride = max(1, n // PLAN_SUBSET)
    positions = np.concatenate([chunk.points[::stride] for chunk in quadrature.chunks()])
    return estimated_cost(positions, points, k, centre, tol, count=n)[0], direct


def make_radiator(points: ArrayLike, k: float, device: str | None = "cpu", block: int | None = None,
                  radiator: str = "fast", tol: float = DEFAULT_TOL, centre: ArrayLike | None = None,
                  domain: Domain | None = None, cache: dict | None = None,
                  force: bool = False, plans: dict | None = None,
                  batch_bytes: int | None = None) -> Radiator | FastRadiator:
    """A radiator of the chosen method: ``fast`` (multilevel where cheaper, else direct; needs
    ``centre``, the targets' sphere centre; ``force``: multilevel whatever the cost estimate,
    for tests and benchmarks; ``plans``, ``batch_bytes``: trees shared with other radiators and
    the elements kept at most, as :class:`FastRadiator`) or ``direct`` (the reference sum)."""
    if radiator not in RADIATORS:
        raise RaysimError(f"unknown radiator {radiator!r}: use one of {', '.join(RADIATORS)}")
    if radiator == "direct" or centre is None:
        return Radiator(points, k, device, block=block)
    return FastRadiator(points, k, device, block=block, tol=tol, centre=centre, domain=domain, cache=cache,
                        force=force, plans=plans, batch_bytes=batch_bytes)
