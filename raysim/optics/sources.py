"""A reflector's radiating elements under one incident wave, made once and radiated onto any
set of field points: what a block of sphere points is computed from.

Frame and units of docs/physics.md (reflector frame, metres, SI fields). :class:`Sources` holds the
PO current elements of :func:`raysim.optics.po.po_elements` (in the quadrature's chunks, in its
order) and, with ``edges``, the fringe elements of :mod:`raysim.optics.ptd` on those edges.
:meth:`Sources.radiate` sums them at the points given through :class:`~raysim.optics.radiator.Radiator`
and returns the raw sums (before the constant prefactors, :func:`~raysim.optics.radiator.field_of`).

Why blocks agree with the whole bit for bit: the radiator's kernels sum per field point, over
the elements chunk by chunk and, inside a chunk, in launches of a fixed number of elements; what
a point gets never depends on the other points of its launch. On the CPU the kernel takes four
points per thread, each with its own accumulators: a block that starts at a multiple of four
keeps every point in the same lane, so :data:`BLOCK_ALIGN` is the granularity of any split.

With ``keep`` the elements are kept (on the device) after the first pass, so every later block
radiates them without recomputing the currents or the shadow test; a plan whose elements
would exceed :data:`KEEP_BYTES` (``RAYSIM_ELEMENT_CACHE_MB``, default 4096 MiB) is streamed
instead, chunk by chunk on each pass, as a single-process run always does.
"""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.errors import RaysimError
from raysim.optics import runtime
from raysim.optics.bvh import ReflectorBVH
from raysim.optics.fast.chart import Domain
from raysim.optics.fast.radiator import DEFAULT_TOL, RADIATORS, make_radiator
from raysim.optics.illumination import Illumination
from raysim.optics.po import ElementStats, po_elements
from raysim.optics.radiator import position_extent
from raysim.progress import Progress
from raysim.surface.mesh import Reflector
from raysim.surface.quadrature import Targets, plan

BLOCK_ALIGN = 4  # points: the CPU kernel's tile; blocks start at multiples of it
BYTES_PER_ELEMENT = 9 * 8  # a PO element in the kernels' (9, N) float64 layout
KEEP_BYTES = int(os.environ.get("RAYSIM_ELEMENT_CACHE_MB", "4096")) << 20
FRINGE_BLOCK = 1024  # elements per launch of the fringe kernels (as ptd.edge_field)


@dataclass(frozen=True)
class Radiated:
    """Raw sums of one :meth:`Sources.radiate` call and what it cost.

    ``sums``: kind (``electric``, ``fringe``) -> (n, 6) float64; ``pairs``: PO element x point
    pairs summed, in ``seconds`` of radiation wall time; ``pairs_edges`` and ``seconds_edges``
    the same for the fringe elements.
    """

    sums: dict[str, NDArray[np.float64]]
    pairs: int
    seconds: float
    pairs_edges: int = 0
    seconds_edges: float = 0.0


class Sources:
    """The PO (and optionally PTD fringe) elements of ``reflector`` under ``wave``.

    Parameters
    ----------
    reflector : the reflector (its smooth surface lifts the quadrature where it has one).
    wave : the incident plane wave.
    samples_per_wavelength : PO quadrature (Gauss points per wavelength along face edges).
    edges : None (PO alone), ``rim`` or ``all``: the free edges that carry fringe currents.
    device : Warp device.
    keep : keep the PO elements after the first pass (several blocks per process).
    edge_points_per_wavelength : Gauss points per wavelength along the edges.
    radiator, tol : the sum (``fast`` or ``direct``) and the fast sum's tolerance.
    plans : a dict given to the Sources of another reflector too (the ideal and the deformed
        one of a simulation): the fast radiator's trees are planned once and shared where
        they serve both (:class:`raysim.optics.fast.radiator.FastRadiator`'s ``plans``).
    targets : where the fields are wanted (:class:`raysim.surface.quadrature.Targets`): the
        quadrature then follows the integrand's own rate (:func:`raysim.surface.quadrature.plan`);
        None: ``samples_per_wavelength`` everywhere.
    """

    def __init__(self, reflector: Reflector, wave: Illumination, samples_per_wavelength: float,
                 edges: str | None = None, device: str | None = "cpu", keep: bool = True,
                 edge_points_per_wavelength: float | None = None, radiator: str = "direct",
                 tol: float = DEFAULT_TOL, plans: dict | None = None,
                 targets: Targets | None = None) -> None:
        from raysim.optics import ptd

        if radiator not in RADIATORS:
            raise RaysimError(f"unknown radiator {radiator!r}: use one of {', '.join(RADIATORS)}")
        self.radiator, self.tol = radiator, float(tol)
        self._fast_cache: dict = {}  # the fast radiator's stop-level grids, per domain
        self._plans = plans  # trees shared with another reflector's Sources (FastRadiator's plans)
        self.methods: dict[str, str] = {}  # kind -> which sum ran last (fast radiator)
        self.device = runtime.resolve_device(device)
        self.reflector, self.wave = reflector, wave
        self.quadrature = plan(reflector, wave.wavelength, samples_per_wavelength, targets)
        self.bvh = ReflectorBVH.build(reflector, self.device)
        self.keep = bool(keep) and BYTES_PER_ELEMENT * self.quadrature.n_samples <= KEEP_BYTES
        self.edges = edges
        self.stats = ElementStats()
        self._kept: list[tuple[Any, tuple[NDArray, NDArray]]] | None = None
        self._fringe_digest = b""
        self._po_digest: bytes | None = None
        self.fringe: Any = None
        self.n_edge_points = self.n_edge_lit = 0
        if edges is not None:
            ppw = ptd.DEFAULT_POINTS_PER_WAVELENGTH if edge_points_per_wavelength is None \
                else edge_points_per_wavelength
            if not ppw > 0:
                raise RaysimError(f"edge points per wavelength must be > 0, got {ppw:g}")
            from raysim.surface.edges import edge_quadrature

            quad = edge_quadrature(reflector, wave.wavelength / ppw, edges, curve=True)
            lit = ptd.lit_points(reflector, quad, wave, self.device, bvh=self.bvh)
            packed = np.ascontiguousarray(ptd.fringe_elements(quad, wave, lit))
            self._fringe_digest = hashlib.blake2b(packed.tobytes(), digest_size=16).digest()
            self.n_edge_points, self.n_edge_lit = len(quad), int(lit.sum())
            if packed.shape[1]:
                wp = runtime.init()
                self.fringe = (wp.array(packed, dtype=wp.float64, device=self.device),
                               position_extent(packed))

    # --- the PO elements, kept or streamed ---------------------------------------------------
    def _po(self) -> Iterator[tuple[Any, tuple[NDArray, NDArray] | None]]:
        """(elements, extent) chunk by chunk, always in the quadrature's order."""
        if self._kept is not None:
            yield from self._kept
            return
        first = self._po_digest is None
        stats, digest, kept = ElementStats(), hashlib.blake2b(digest_size=16), []
        for src in po_elements(self.reflector, self.wave, self.quadrature, self.device,
                               stats=stats, bvh=self.bvh):
            extent = None
            if first or self.keep:
                host = src.numpy()  # a view on the CPU, a copy from a GPU
                extent = (host[:3].min(axis=1), host[:3].max(axis=1))
                if first:
                    digest.update(np.ascontiguousarray(host).tobytes())
            if self.keep:
                kept.append((src, extent))
            yield src, extent
        if first:  # a pass run to its end: the counts and the digest stand
            self.stats, self._po_digest = stats, digest.digest()
        if self.keep:
            self._kept = kept

    def prime(self) -> None:
        """Make the elements once (counts and digest known) without radiating them."""
        if self._po_digest is None:
            for _ in self._po():
                pass

    @property
    def n_elements(self) -> int:
        """Lit PO elements (after the first pass)."""
        return self.stats.n_lit

    def digest(self) -> str:
        """Hex digest of every element's bytes (PO and fringe): equal digests, equal sums."""
        self.prime()
        return hashlib.blake2b(self._fringe_digest + (self._po_digest or b""), digest_size=16).hexdigest()

    # --- radiation ---------------------------------------------------------------------------
    def _radiator(self, pts: NDArray[np.float64], domain: Domain | None, block: int | None = None):
        return make_radiator(pts, self.wave.k, self.device, block=block, radiator=self.radiator,
                             tol=self.tol, centre=(0.0, 0.0, float(self.reflector.F)), domain=domain,
                             cache=self._fast_cache, plans=self._plans)

    def radiate(self, points: ArrayLike, progress: Progress | None = None,
                domain: Domain | None = None) -> Radiated:
        """Raw sums of the elements at ``points`` (n, 3), m, reflector frame. ``domain``: the
        whole job's points (:func:`raysim.optics.fast.chart.domain_of`), so that the fast
        radiator gives every block the bits of the whole."""
        return self.start(points, progress, domain)()

    def start(self, points: ArrayLike, progress: Progress | None = None,
              domain: Domain | None = None) -> Callable[[], Radiated]:
        """:meth:`radiate` in two halves: the elements are made and handed to the radiators,
        and the fast radiator's trees planned (and shared through ``plans``), here; the sums
        are run by the function returned. Sources sharing ``plans`` started one after another
        may have their sums run at once on separate threads, with the bits of running them in
        that order."""
        report = progress or (lambda stage, fraction: None)
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        po = self._radiator(pts, domain)
        expected = max(self.stats.n_lit if self._po_digest is not None else self.quadrature.n_samples, 1)
        done = 0
        report("currents", 0.0)
        for src, extent in self._po():
            base, size = done, src.shape[1]

            def sub(stage: str, f: float, base: int = base, size: int = size) -> None:
                report(f"radiating, {stage}", min(1.0, (base + f * size) / expected))

            po.add_packed(src, "electric", sub, extent=extent)
            done += size
        fr = None
        if self.edges is not None:
            fr = self._radiator(pts, domain, FRINGE_BLOCK)
            if self.fringe is not None:
                fr.add_packed(self.fringe[0], "fringe", extent=self.fringe[1])
        for radiator in (po, fr):
            if hasattr(radiator, "prepare"):
                radiator.prepare()

        def sums() -> Radiated:
            out = {"electric": po.sums_of("electric")}
            self.methods.update(getattr(po, "method", {}))
            if fr is None:
                return Radiated(out, po.pairs, po.seconds)
            start = time.perf_counter()
            out["fringe"] = fr.sums_of("fringe")
            self.methods.update(getattr(fr, "method", {}))
            return Radiated(out, po.pairs, po.seconds, fr.pairs, time.perf_counter() - start)

        return sums
