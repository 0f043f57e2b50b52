"""The one host-side radiator: the field of current elements at fixed points, in float64.

Every current-based engine (PO's surface currents, PTD's fringe edge currents, and any other)
packs its elements column-wise in the layout of its kernel module and adds them to a
:class:`Radiator` under a *kind*; the radiator launches that kind's summation kernels of
:mod:`raysim.optics.kernels.radiation` in blocks, split over the field points on the CPU's
threads, and applies the kind's constant prefactor once when the field is read. Fields of
different kinds on the same points add (superposition).

Kinds: ``electric`` and ``magnetic`` (:mod:`raysim.optics.kernels.po`, (9, N): position,
moment J dA / I dl in A m or M dA / K dl in V m), ``fringe`` (:mod:`raysim.optics.kernels.ptd`,
(23, N), prefactors already inside the coefficients), ``diffraction``
(:mod:`raysim.optics.kernels.goedge`: fringe plus PO end-point currents of an edge, prefactors
inside), ``shift`` (:mod:`raysim.optics.kernels.po_derivative`, (18, N): an electric element
moving as its moment changes, the first-order field change that a surface perturbation makes;
electric prefactor).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.errors import RaysimError
from raysim.optics import runtime
from raysim.optics.illumination import ETA0
from raysim.progress import Progress


@dataclass(frozen=True)
class Kind:
    """One kind of element: its kernels, its row count and its prefactor as a function of k."""

    rows: int
    kernels: tuple[Any, Any]  # (one point per thread, four points per thread)
    prefactor: Any  # k (rad/m) -> complex


#: each kind's constant prefactor as a function of k (rad/m), applied once when a field is read
PREFACTORS: dict[str, Any] = {
    "electric": lambda k: -1j * k * ETA0 / (4.0 * np.pi),
    "magnetic": lambda k: 1j * k / (4.0 * np.pi),
    "fringe": lambda k: 1.0,
    "diffraction": lambda k: 1.0,  # go+edge: prefactors inside the coefficients, as fringe
    "shift": lambda k: -1j * k * ETA0 / (4.0 * np.pi),  # a moving electric element
}


def _kinds() -> dict[str, Kind]:
    from raysim.optics.kernels import goedge, po, po_derivative, ptd

    return {
        "electric": Kind(po.ROWS, (po.radiate_electric, po.radiate_electric4), PREFACTORS["electric"]),
        "magnetic": Kind(po.ROWS, (po.radiate_magnetic, po.radiate_magnetic4), PREFACTORS["magnetic"]),
        "fringe": Kind(ptd.ROWS, (ptd.radiate_fringe, ptd.radiate_fringe4), PREFACTORS["fringe"]),
        "diffraction": Kind(goedge.ROWS, (goedge.radiate_diffraction, goedge.radiate_diffraction4),
                            PREFACTORS["diffraction"]),
        "shift": Kind(po_derivative.SHIFT_ROWS,
                      (po_derivative.radiate_shift, po_derivative.radiate_shift4),
                      PREFACTORS["shift"]),
    }


def field_of(sums: Mapping[str, NDArray[np.float64]], k: float) -> NDArray[np.complex128]:
    """E (n, 3) complex (V/m) from a radiator's raw sums: kind -> (n, 6) float64 (Re x, y, z,
    Im x, y, z before the kind's prefactor), as :meth:`Radiator.sums_of` gives them.

    Elementwise per point: a field assembled from blocks of points is the field of the whole.
    """
    E: NDArray[np.complex128] | None = None
    for kind, a in sums.items():
        a = np.asarray(a, dtype=np.float64)
        term = PREFACTORS[kind](k) * (a[:, :3] + 1j * a[:, 3:])
        E = term if E is None else E + term
    if E is None:
        raise RaysimError("no radiator sums to make a field from")
    return E


@dataclass(frozen=True)
class CurrentElements:
    """Point current elements (reflector frame).

    ``positions`` (N, 3) in m; ``moments`` (N, 3) complex: J dA or I dl in A m for electric
    elements, M dA or K dl in V m for magnetic ones (``magnetic`` True).
    """

    positions: NDArray[np.float64]
    moments: NDArray[np.complex128]
    magnetic: bool = False

    def __len__(self) -> int:
        return len(self.positions)

    @property
    def kind(self) -> str:
        return "magnetic" if self.magnetic else "electric"

    def packed(self) -> NDArray[np.float64]:
        """The (9, N) float64 layout of the kernels: position, Re moment, Im moment."""
        m = np.asarray(self.moments, dtype=np.complex128)
        return np.ascontiguousarray(np.vstack([np.asarray(self.positions, dtype=np.float64).T,
                                               m.real.T, m.imag.T]))


class Radiator:
    """The field (V/m) of current elements at fixed points, accumulated in float64.

    Parameters
    ----------
    points : (n, 3) field points (m, reflector frame).
    k : wavenumber (rad/m).
    device : Warp device (``cpu``, ``cuda``, ``cuda:N``).
    block : elements per launch (a cache-sized block on the CPU; each field point sums a
        block in registers, then adds it to its total: a two-level sum).
    tile : field points per kernel thread: 4 on the CPU (each element is loaded once for four
        points), 1 on CUDA; None picks by device.
    """

    def __init__(self, points: ArrayLike, k: float, device: str | None = "cpu",
                 block: int | None = None, tile: int | None = None) -> None:
        from raysim.optics.kernels import radiation

        self.wp = runtime.init()
        self.device = runtime.resolve_device(device)
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        self.n = len(pts)
        self.k = float(k)
        cpu = self.device == "cpu"
        self.tile = int(tile or (4 if cpu else 1))
        if self.tile not in (1, 4):
            raise RaysimError(f"tile must be 1 or 4, got {self.tile}")
        # the four-point kernels need a multiple of four points: pad with copies of the last
        self.n_pad = -(-self.n // self.tile) * self.tile
        padded = np.vstack([pts, np.repeat(pts[-1:], self.n_pad - self.n, axis=0)]) if self.n else pts
        wp = self.wp
        self.field_points = wp.array(np.ascontiguousarray(padded.T), dtype=wp.float64, device=self.device)
        self.table = wp.array(radiation.cis_table(), dtype=wp.vec2d, device=self.device)
        self.max_phase = radiation.MAX_PHASE
        self.block = int(block or (2048 if cpu else 16384))
        self.kinds = _kinds()
        self.sums: dict[str, Any] = {}
        self.pairs = 0
        self.seconds = 0.0
        self._bounds = (pts.min(axis=0), pts.max(axis=0)) if self.n else (np.zeros(3), np.zeros(3))

    def add(self, elements: CurrentElements, progress: Progress | None = None) -> None:
        """Add the field of ``elements`` at every point."""
        if len(elements) == 0:
            return
        self.add_packed(elements.packed(), elements.kind, progress)

    def add_packed(self, src: Any, kind: str = "electric", progress: Progress | None = None,
                   extent: tuple[NDArray, NDArray] | None = None) -> None:
        """Add elements of ``kind`` already packed in its kernel layout (numpy or Warp float64).

        ``extent``: the (lowest, highest) corner (m) of a box holding the elements' positions,
        when the caller knows it; otherwise it is read from ``src`` (a copy from a GPU).
        """
        spec = self.kinds[kind]
        wp = self.wp
        if not isinstance(src, wp.array):
            src = wp.array(np.ascontiguousarray(src, dtype=np.float64), dtype=wp.float64, device=self.device)
        if src.shape[0] != spec.rows:
            raise RaysimError(f"{kind} elements have {spec.rows} rows, got {src.shape[0]}")
        n_src = src.shape[1]
        if n_src == 0 or self.n == 0:
            return
        self._check_phase(position_extent(src) if extent is None else extent)
        if kind not in self.sums:
            self.sums[kind] = wp.zeros((6, self.n_pad), dtype=wp.float64, device=self.device)
        kernel = spec.kernels[1] if self.tile == 4 else spec.kernels[0]
        dim = self.n_pad // self.tile
        for begin in range(0, n_src, self.block):
            end = min(begin + self.block, n_src)
            start = time.perf_counter()
            runtime.launch(kernel, dim, [self.field_points, src, begin, end, self.k, 1.0 / self.k,
                                         self.table, self.sums[kind]], self.device, min_chunk=16)
            self.seconds += time.perf_counter() - start
            self.pairs += (end - begin) * self.n
            if progress is not None:
                progress(f"{self.rate() / 1e6:.0f} M pairs/s", end / n_src)

    def _check_phase(self, extent: tuple[NDArray, NDArray]) -> None:
        """The kernels' phase reduction holds for kR < MAX_PHASE: refuse anything beyond."""
        lo = np.minimum(extent[0], self._bounds[0])
        hi = np.maximum(extent[1], self._bounds[1])
        reach = float(np.linalg.norm(hi - lo))  # bounds any element-to-point distance (m)
        if self.k * reach >= self.max_phase:
            raise RaysimError(f"k R up to {self.k * reach:.3g} rad exceeds the kernel's phase "
                              f"range {self.max_phase:.3g} rad: lower the frequency")

    def rate(self) -> float:
        """Pairs (element x field point) per second so far."""
        return self.pairs / self.seconds if self.seconds > 0 else 0.0

    def sums_of(self, kind: str) -> NDArray[np.float64]:
        """The raw sums (n, 6) float64 of ``kind`` at the points (zeros when none was added):
        Re and Im of x, y, z before the kind's prefactor (see :func:`field_of`)."""
        if kind not in self.sums:
            return np.zeros((self.n, 6))
        return np.ascontiguousarray(self.sums[kind].numpy()[:, : self.n].T)

    def field(self, kinds: tuple[str, ...] | None = None) -> NDArray[np.complex128]:
        """E (n, 3) complex (V/m) of everything added so far (or of the ``kinds`` named)."""
        chosen = [kind for kind in self.sums if kinds is None or kind in kinds]
        if not chosen:
            return np.zeros((self.n, 3), dtype=np.complex128)
        return field_of({kind: self.sums_of(kind) for kind in chosen}, self.k)


def position_extent(src: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(lowest, highest) corner (m) of the positions (rows 0-2) of packed elements ``src``
    (numpy, or Warp on any device: read back to the host)."""
    rows = src.numpy()[:3] if hasattr(src, "numpy") else np.asarray(src)[:3]
    return rows.min(axis=1), rows.max(axis=1)
