"""The target sphere's angles, its spectral grids, and the Lagrange interpolation of the last step.

Targets lie on a sphere of radius R (m) about a centre c0 (reflector frame, the focus). Angles
as the sphere grid's (docs/conventions.md): theta between P - c0 and -z (0 faces the dish),
phi = atan2(y, x); P = c0 + R (sin theta cos phi, sin theta sin phi, -cos theta).

Why a double-covered torus: that formula gives the same point for (theta, phi) and
(2 pi - theta, phi + pi), so a smooth function on the sphere, read on the whole square
[0, 2 pi)^2 of angles, is 2 pi-periodic in both. When its spherical-harmonic degree stays below
L, its 2-D Fourier series has no frequency of modulus L or more along either angle, so an
n x n grid with n > 2 L holds it exactly and zero-padding its spectrum interpolates it to any
finer grid (the standard device of fast multipole codes on the sphere; e.g. Chew, Jin,
Michielssen and Song, *Fast and Efficient Algorithms in Computational Electromagnetics*, 2001,
ch. 3). Rows theta_i > pi repeat rows 2 pi - theta_i shifted by half a turn in phi, so only the
rows 0 <= theta_i <= pi are ever computed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
import scipy.fft as sfft
from numpy.typing import ArrayLike, NDArray

#: threads of the FFTs (the machine's cores, as Warp's CPU launches use)
FFT_WORKERS = -1


@dataclass(frozen=True)
class Domain:
    """Where a radiator's targets lie: the sphere (``centre`` (3,) m, ``radius`` m) and
    ``count``, the number of targets of the whole job (its cost estimates use it). When the
    job's targets are every pair of a set of polar angles ``thetas`` and azimuths ``phis``
    (rad, ascending; a sphere grid, or a subgrid of one), they are recorded: the last step then
    evaluates the stop level's series on that grid exactly. Blocks of one job given the same
    Domain give bit-identical fields."""

    centre: tuple[float, float, float]
    radius: float
    count: int
    thetas: tuple[float, ...] | None = None
    phis: tuple[float, ...] | None = None

    @property
    def tensor(self) -> bool:
        return self.thetas is not None and self.phis is not None


#: angles closer than this (rad) are one row or one column of a tensor grid
ANGLE_TOL = 1e-9


def domain_of(points: ArrayLike, centre: ArrayLike, rel: float = 1e-9) -> Domain | None:
    """The Domain of ``points`` (n, 3) m about ``centre``; None when they are not on one
    sphere about it (within ``rel`` of its radius)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        return None
    r = np.linalg.norm(pts - np.asarray(centre, dtype=np.float64), axis=1)
    R = float(np.median(r))
    if not R > 0 or not np.all(np.isfinite(r)) or np.max(np.abs(r - R)) > rel * R:
        return None
    c = tuple(float(x) for x in np.asarray(centre, dtype=np.float64))
    thetas, phis = _tensor(to_angles(pts, centre))
    return Domain(c, R, len(pts), thetas, phis)  # type: ignore[arg-type]


def _tensor(angles: NDArray[np.float64]) -> tuple[tuple[float, ...] | None, tuple[float, ...] | None]:
    """(thetas, phis) when ``angles`` (n, 2) are every pair of them once, else (None, None)."""
    rows, i = _levels(angles[:, 0])
    cols, j = _levels(angles[:, 1])
    if len(rows) * len(cols) != len(angles) or len(np.unique(i * len(cols) + j)) != len(angles):
        return None, None
    return tuple(float(x) for x in rows), tuple(float(x) for x in cols)


def _levels(x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The distinct values of ``x`` (ascending; values within :data:`ANGLE_TOL` are one) and the
    index of each element's value."""
    order = np.argsort(x, kind="stable")
    new = np.r_[True, np.diff(x[order]) > ANGLE_TOL]
    index = np.empty(len(x), dtype=np.int64)
    index[order] = np.cumsum(new) - 1
    return x[order][new], index


def tensor_index(angles: NDArray[np.float64], domain: Domain) -> NDArray[np.int64] | None:
    """The flat index i * len(phis) + j of each target's (theta_i, phi_j) in ``domain``'s
    tensor grid; None when a target is not on it."""
    if not domain.tensor:
        return None
    out = []
    for column, values in ((0, domain.thetas), (1, domain.phis)):
        v = np.asarray(values)
        i = np.clip(np.searchsorted(v, angles[:, column]), 1, max(len(v) - 1, 1))
        i = np.where(np.abs(v[i - 1] - angles[:, column]) <= np.abs(v[np.minimum(i, len(v) - 1)]
                                                                      - angles[:, column]), i - 1, i)
        i = np.minimum(i, len(v) - 1)
        if np.any(np.abs(v[i] - angles[:, column]) > ANGLE_TOL):
            return None
        out.append(i)
    return out[0] * len(domain.phis) + out[1]  # type: ignore[arg-type]


def to_angles(points: ArrayLike, centre: ArrayLike) -> NDArray[np.float64]:
    """(theta, phi) (n, 2) rad of ``points`` (n, 3) about ``centre``: theta in [0, pi], phi in
    [0, 2 pi)."""
    d = np.asarray(points, dtype=np.float64).reshape(-1, 3) - np.asarray(centre, dtype=np.float64)
    theta = np.arctan2(np.hypot(d[:, 0], d[:, 1]), -d[:, 2])
    phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2.0 * np.pi)
    return np.column_stack([theta, phi])


def grid_points(n: int, domain: Domain, rows: int | None = None) -> NDArray[np.float64]:
    """Points (rows * n, 3) m of the n x n angle grid theta_i = phi_i = 2 pi i / n, rows
    0 .. rows - 1 (default: every row); row-major (theta, then phi)."""
    t = 2.0 * np.pi * np.arange(n) / n
    th, ph = np.meshgrid(t[: (n if rows is None else rows)], t, indexing="ij")
    s = np.sin(th)
    d = np.stack([s * np.cos(ph), s * np.sin(ph), -np.cos(th)], axis=-1).reshape(-1, 3)
    return np.asarray(domain.centre) + domain.radius * d


def half_rows(n: int) -> int:
    """The rows theta_i <= pi of an n x n grid (n even): the ones a leaf computes."""
    return n // 2 + 1


def mirror(half: NDArray[np.complex128], n: int) -> NDArray[np.complex128]:
    """The whole (..., n, n, c) grid from its rows 0 .. n/2 (..., n/2 + 1, n, c): row
    n - i is row i shifted by half a turn in phi (the same points)."""
    full = np.empty((*half.shape[:-3], n, n, half.shape[-1]), dtype=half.dtype)
    h = n // 2
    full[..., : h + 1, :, :] = half
    rows = half[..., 1:h, :, :][..., ::-1, :, :]  # rows h - 1 .. 1 become rows h + 1 .. n - 1
    full[..., h + 1:, :, :] = np.roll(rows, h, axis=-2)
    return full


def kept_blocks(n: int, m: int):
    """The four (coarse, fine) pairs of index blocks, along both angles, through which an n x n
    spectrum (its frequencies below n / 2 in modulus; the Nyquist ones dropped) sits inside an
    m x m one (m = n - 1: the kept coefficients packed, frequencies 0 .. n/2 - 1, then the
    negative ones)."""
    h = n // 2
    along = ((slice(0, h), slice(0, h)), (slice(n - h + 1, n), slice(m - h + 1, m)))
    for coarse_u, fine_u in along:
        for coarse_v, fine_v in along:
            yield (..., coarse_u, coarse_v, slice(None)), (..., fine_u, fine_v, slice(None))


def resample(G: NDArray[np.complex128], m: int, out: NDArray[np.complex128] | None = None,
             overwrite: bool = False) -> NDArray[np.complex128]:
    """The periodic grids ``G`` (..., n, n, c) on the finer m x m grid (m >= n, even n):
    spectra zero-padded. The Nyquist row and column are dropped (a grid chosen by
    :func:`size_for` holds nothing there). ``out``: a (..., m, m, c) buffer the result may be
    built in (one reused between calls, :mod:`raysim.optics.fast.scratch`; read the returned
    array, a view of ``G`` when m = n); ``overwrite``: ``G`` may be overwritten (its spectrum
    is taken in place). :func:`resample_rows` with every row."""
    return resample_rows(G, m, m, out=out, overwrite=overwrite)


def resample_rows(G: NDArray[np.complex128], m: int, rows: int, out: NDArray[np.complex128] | None = None,
                  scratch: Any = None, overwrite: bool = False) -> NDArray[np.complex128]:
    """Rows 0 .. rows - 1 (..., rows, m, c) of ``G`` (..., n, n, c) refined to m x m
    (:func:`resample`): the spectra are zero-padded and transformed along theta first, and only
    the rows wanted are then transformed along phi, so about half the cost of the whole grid
    when ``rows`` is about m / 2 (the aggregation reads a refined child at its parent's rows
    theta <= pi alone). ``out``: a (..., rows, m, c) buffer the result may be built in (read
    the returned array); ``scratch``: a :class:`~raysim.optics.fast.scratch.Scratch` whose role
    "theta" holds the first stage, else a new array; ``overwrite``: ``G`` may be overwritten."""
    n = G.shape[-2]
    if m == n:
        return G[..., :rows, :, :]
    lead, c, h = G.shape[:-3], G.shape[-1], n // 2
    S = sfft.fft2(G, axes=(-3, -2), workers=FFT_WORKERS, overwrite_x=overwrite)
    S *= (m * m) / (n * n)  # the inverse transforms' 1 / m^2 against the forward one's n^2
    # theta's frequencies padded to m, phi's n - 1 kept ones packed (0 .. h - 1, then -h + 1 .. -1)
    shape = (*lead, m, n - 1, c)
    T = np.empty(shape, dtype=np.complex128) if scratch is None else scratch.array("theta", shape)
    T[..., h:m - h + 1, :, :] = 0.0
    T[..., :h, :h, :] = S[..., :h, :h, :]
    T[..., :h, h:, :] = S[..., :h, n - h + 1:, :]
    T[..., m - h + 1:, :h, :] = S[..., n - h + 1:, :h, :]
    T[..., m - h + 1:, h:, :] = S[..., n - h + 1:, n - h + 1:, :]
    T = sfft.ifft(T, axis=-3, workers=FFT_WORKERS, overwrite_x=True)
    if out is None:
        out = np.empty((*lead, rows, m, c), dtype=np.complex128)
    out[..., :, h:m - h + 1, :] = 0.0
    out[..., :, :h, :] = T[..., :rows, :h, :]
    out[..., :, m - h + 1:, :] = T[..., :rows, h:, :]
    return sfft.ifft(out, axis=-2, workers=FFT_WORKERS, overwrite_x=True)


@dataclass(frozen=True)
class Turn:
    """Angles x0 + 2 pi i / period, i = 0 .. count - 1 (rad): a uniform axis whose step divides
    the full turn (a sphere grid's thetas and phis, the paper's 0.5 + i degrees)."""

    x0: float
    period: int
    count: int


#: how far (rad) an axis's angles may lie from x0 + 2 pi i / period to be read as a :class:`Turn`:
#: the series' phase at degree L moves by L times this, 1e-10 at the degrees the grids reach
TURN_TOL = 1e-13


def turn_of(angles: ArrayLike) -> Turn | None:
    """The :class:`Turn` the ascending ``angles`` (rad) are, or None when they are not one."""
    x = np.asarray(angles, dtype=np.float64)
    if len(x) == 1:
        return Turn(float(x[0]), 1, 1)  # one angle: every frequency folds onto it
    if len(x) == 0 or not x[-1] > x[0]:
        return None
    period = 2.0 * np.pi * (len(x) - 1) / (x[-1] - x[0])
    p = round(float(period))
    if p < len(x) or abs(period - p) > 1e-9 * period:
        return None
    if np.max(np.abs(x - (x[0] + 2.0 * np.pi * np.arange(len(x)) / p))) > TURN_TOL:
        return None
    return Turn(float(x[0]), p, len(x))


#: an FFT's cost per point and halving, in complex multiply-adds of a matrix product (pocketfft
#: against OpenBLAS on one core: a product runs about ten times as many operations a second)
FFT_POINT_COST = 10.0


def _fft_madds(period: int) -> float:
    """An inverse FFT of ``period`` points in complex multiply-adds of a matrix product."""
    return FFT_POINT_COST * period * math.log2(max(period, 2))


def by_fft(n: int, turn: Turn | None, count: int) -> bool:
    """Whether :func:`series_at` sums an n-point spectrum at ``count`` angles (``turn``: their
    :class:`Turn`, or None) by an inverse FFT rather than by the product with the basis."""
    return turn is not None and _fft_madds(turn.period) < n * count


def series_cost(n: int, angles: ArrayLike) -> float:
    """Complex multiply-adds of :func:`series_at` per column (one leading and trailing index) of
    an n-point spectrum at ``angles``, as it will run."""
    count = len(np.atleast_1d(angles))
    turn = turn_of(angles)
    return _fft_madds(turn.period) if turn is not None and by_fft(n, turn, count) else float(n * count)


def series_at(S: NDArray[np.complex128], axis: int, angles: ArrayLike) -> NDArray[np.complex128]:
    """The Fourier series along ``axis`` of the coefficients ``S`` (an n-point DFT's order:
    frequencies 0 .. n/2 - 1, the Nyquist one, then -(n/2 - 1) .. -1; the Nyquist one is
    dropped, as :func:`resample` does) summed at ``angles`` (rad): sum_m S_m exp(j m x).

    Where the angles are a :class:`Turn` and the period is short enough, it is one inverse FFT
    of the period's length (the coefficients shifted by exp(j m x0) and, on a period shorter
    than n, folded onto their frequencies modulo it: still exact); otherwise (a few angles of a
    long period, as a sphere grid's thetas over a quarter turn, or angles that are no Turn) the
    product with the basis exp(j m x) (angles by n), one matrix product per leading index.
    n is even, as :func:`size_for` makes every grid."""
    n = S.shape[axis]
    if n % 2:
        raise ValueError(f"series_at: the spectrum's length must be even, got {n}")
    h = n // 2
    x = np.asarray(angles, dtype=np.float64)
    turn = turn_of(x)
    if not by_fft(n, turn, len(x)):
        m = np.r_[0:h, 0, -(h - 1):0]
        basis = np.exp(1j * np.outer(x, m))  # (count, n)
        basis[:, h] = 0.0  # the Nyquist frequency
        lead, trail = S.shape[:axis], S.shape[axis + 1:]
        flat = np.ascontiguousarray(S).reshape(math.prod(lead), n, math.prod(trail))
        return np.matmul(basis, flat).reshape(*lead, len(x), *trail)
    m = np.arange(-(h - 1), h)  # the kept frequencies, ascending
    P = turn.period
    shape = list(S.shape)
    shape[axis] = P
    B = np.zeros(shape, dtype=np.complex128)
    along = [1] * S.ndim
    along[axis] = -1
    shift = np.exp(1j * m * turn.x0)

    def at(i: Any) -> tuple:
        index: list[Any] = [slice(None)] * S.ndim
        index[axis] = i
        return tuple(index)

    def by(w: NDArray[np.complex128]) -> NDArray[np.complex128]:  # broadcast along the axis
        return w.reshape(along)

    if P >= n - 1:  # the negative frequencies at the period's end, as a DFT orders them
        B[at(slice(0, h))] = S[at(slice(0, h))] * by(shift[h - 1:])
        B[at(slice(P - h + 1, P))] = S[at(slice(n - h + 1, n))] * by(shift[:h - 1])
    else:  # a period shorter than the grid: P consecutive frequencies fall in distinct bins
        kept = np.take(S, np.mod(m, n), axis=axis) * by(shift)
        bins = np.mod(m, P)
        for j0 in range(0, len(m), P):
            B[at(bins[j0:j0 + P])] += kept[at(slice(j0, j0 + P))]
    Y = sfft.ifft(B, axis=axis, norm="forward", workers=FFT_WORKERS, overwrite_x=True)
    return Y[at(slice(0, turn.count))]


def restrict(X: NDArray[np.complex128], n: int, overwrite: bool = False) -> NDArray[np.complex128]:
    """The transpose of :func:`resample` (m x m -> n x n): weights on the fine grid taken back to
    the coarse one (both DFT matrices are symmetric, so the transpose of zero-padding the
    spectrum is truncating it, between the same two transforms swapped). ``overwrite``: ``X``
    may be overwritten (its transform is taken in place)."""
    m = X.shape[-2]
    if m == n:
        return X
    T = sfft.ifft2(X, axes=(-3, -2), workers=FFT_WORKERS, overwrite_x=overwrite)
    S = np.zeros((*X.shape[:-3], n, n, X.shape[-1]), dtype=np.complex128)
    for coarse, fine in kept_blocks(n, m):
        S[coarse] = T[fine]
    S = sfft.fft2(S, axes=(-3, -2), workers=FFT_WORKERS, overwrite_x=True)
    S *= (m * m) / (n * n)
    return S


def fold(full: NDArray[np.complex128], n: int) -> NDArray[np.complex128]:
    """The transpose of :func:`mirror`: weights on the whole (..., n, n, c) grid gathered onto
    its rows 0 .. n/2 (..., n/2 + 1, n, c)."""
    h = n // 2
    half = full[..., : h + 1, :, :].copy()
    half[..., 1:h, :, :] += np.roll(full[..., h + 1:, :, :], -h, axis=-2)[..., ::-1, :, :]
    return half


def degree_for(bandwidth: Any, digits: float, nearness: Any = 0.1) -> Any:
    """The harmonic degree L that holds a field of phase bandwidth ``bandwidth`` (rad per rad
    of angle; a number or an array of them) to about 10^-digits: an excess bandwidth of the
    multipole rule's form (Song and Chew: c d^(2/3) (k a)^(1/3)) plus a floor for the
    amplitude's own variation. The amplitude (1/|P - s| and the near-field terms) of a source
    at distance D from the sphere's centre, read on the sphere of radius R, has harmonics
    falling as q^l, q = R / D (the generating function of the Legendre polynomials): the floor
    is d / log10(1 / q), ``nearness`` being q for the cluster's nearest source, and never less
    than d (its value at q = 1/10). The constant 1.2 is measured
    (tests/raysim/optics/test_fast_radiator.py keeps it honest)."""
    excess = 1.2 * digits ** (2.0 / 3.0) * np.maximum(bandwidth, 1.0) ** (1.0 / 3.0) + digits
    with np.errstate(divide="ignore"):
        floor = digits / -np.log10(np.clip(nearness, 0.0, 1.0))
    return bandwidth + np.maximum(excess, floor)


def size_for(degree: float) -> int:
    """An even, FFT-friendly n > 2 * degree (+ 2 for the dropped Nyquist row)."""
    n = sfft.next_fast_len(2 * math.ceil(degree) + 2)
    while n % 2:
        n = sfft.next_fast_len(n + 1)
    return n


@dataclass(frozen=True)
class Axis:
    """A uniform 1-D grid: ``n`` nodes ``start + i h``."""

    start: float
    h: float
    n: int

    @property
    def nodes(self) -> NDArray[np.float64]:
        return self.start + self.h * np.arange(self.n)


def lagrange(x: ArrayLike, axis: Axis, p: int) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """First node index (m,) and weights (m, p) of p-point Lagrange interpolation at ``x``."""
    x = np.asarray(x, dtype=np.float64)
    t = (x - axis.start) / axis.h
    i0 = np.clip(np.floor(t).astype(np.int64) - (p // 2 - 1), 0, axis.n - p)
    s = t - i0  # position in node units from the first node of the stencil
    nodes = np.arange(p, dtype=np.float64)
    w = np.ones((len(x), p))
    for j in range(p):
        for m in range(p):
            if m != j:
                w[:, j] *= (s - nodes[m]) / (nodes[j] - nodes[m])
    return i0, w


@lru_cache(maxsize=64)
def lagrange_error(p: int, s: float) -> float:
    """Largest error of centred p-point Lagrange interpolation of exp(j x) on nodes pi / s apart
    (the band-limit B = 1 sampled s times above Nyquist), measured on a fine set of points."""
    h = math.pi / s
    axis = Axis(0.0, h, p + 1)
    x = h * (p // 2 - 1) + h * np.linspace(0.0, 1.0, 201)
    i0, w = lagrange(x, axis, p)
    f = np.exp(1j * axis.nodes)
    approx = np.sum(w * f[i0[:, None] + np.arange(p)], axis=1)
    return float(np.max(np.abs(approx - np.exp(1j * x))))


#: the last step's refinements the plan may choose (the stop level's grids are refined this many
#: times before the targets are interpolated locally)
OVERSAMPLINGS = (4, 6, 8)


def stencil_for(tol: float, oversampling: int) -> int:
    """The smallest even stencil p whose Lagrange error, on a grid refined ``oversampling``
    times above the Nyquist rate, is below ``tol``."""
    for p in range(4, 26, 2):
        if lagrange_error(p, float(oversampling)) <= tol:
            return p
    return 26
