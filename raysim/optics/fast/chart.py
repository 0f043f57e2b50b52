"""The chart of a target sphere and the Lagrange interpolation the fast radiator runs on it.

Targets lie on a sphere of radius R (m) about a centre c0 (reflector frame, the focus). The
chart is stereographic from the pole +z: dir = (P - c0) / R, u = (dir_x, dir_y) / (1 - dir_z),
so theta = 0 (dir = -z, towards the dish) is u = 0 and theta = 90 deg is |u| = 1; it is smooth
everywhere except at dir = +z. On the sphere |dP| = R |du| * 2 / (1 + |u|^2) <= 2 R |du|.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: the largest |u| (theta about 150 deg) the fast radiator charts; beyond, the direct sum runs
U_LIMIT = 3.75


@dataclass(frozen=True)
class Domain:
    """Where a radiator's targets may lie: the sphere (``centre`` (3,) m, ``radius`` m), the
    chart box ``box`` (u0 low, u0 high, u1 low, u1 high) and ``count``, the number of targets
    of the whole job. Blocks of one job given the same Domain give bit-identical fields."""

    centre: tuple[float, float, float]
    radius: float
    box: tuple[float, float, float, float]
    count: int


def to_chart(points: ArrayLike, centre: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(u (n, 2), distance (n,) m) of ``points`` (n, 3) about ``centre``."""
    d = np.asarray(points, dtype=np.float64).reshape(-1, 3) - np.asarray(centre, dtype=np.float64)
    r = np.linalg.norm(d, axis=1)
    # 1 - dir_z written without cancellation near the pole at -z: r - d_z
    denom = r - d[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = d[:, :2] / denom[:, None]
    return u, r


def from_chart(u: ArrayLike, centre: ArrayLike, radius: float) -> NDArray[np.float64]:
    """Points (n, 3) m on the sphere at chart coordinates ``u`` (n, 2)."""
    u = np.asarray(u, dtype=np.float64).reshape(-1, 2)
    rho = np.sum(u * u, axis=1)
    dirs = np.column_stack([2 * u[:, 0], 2 * u[:, 1], rho - 1.0]) / (1.0 + rho)[:, None]
    return np.asarray(centre, dtype=np.float64) + radius * dirs


def domain_of(points: ArrayLike, centre: ArrayLike, rel: float = 1e-9) -> Domain | None:
    """The Domain of ``points`` about ``centre``; None when they are not on one sphere or reach
    beyond :data:`U_LIMIT` on the chart."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        return None
    u, r = to_chart(pts, centre)
    R = float(np.median(r))
    if not R > 0 or np.max(np.abs(r - R)) > rel * R or not np.all(np.isfinite(u)):
        return None
    if np.max(np.abs(u)) > U_LIMIT:
        return None
    c = tuple(float(x) for x in np.asarray(centre, dtype=np.float64))
    box = (float(u[:, 0].min()), float(u[:, 0].max()), float(u[:, 1].min()), float(u[:, 1].max()))
    return Domain(c, R, box, len(pts))  # type: ignore[arg-type]


@dataclass(frozen=True)
class Axis:
    """A uniform 1-D grid of the chart: ``n`` nodes ``start + i h``."""

    start: float
    h: float
    n: int

    @property
    def nodes(self) -> NDArray[np.float64]:
        return self.start + self.h * np.arange(self.n)


def axis_for(lo: float, hi: float, h: float, p: int) -> Axis:
    """Nodes of spacing ``h`` covering [lo, hi] with p nodes of margin each side, so that every
    point of [lo, hi], and of a finer grid's own p / 2-node margin, has a centred p-point
    stencil inside the grid."""
    m = p
    cells = max(1, math.ceil((hi - lo) / h - 1e-9))
    centre = 0.5 * (lo + hi)
    return Axis(centre - 0.5 * cells * h - m * h, h, cells + 2 * m + 1)


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


def choose_order(tol: float) -> tuple[int, float]:
    """(p, s): the cheapest stencil and oversampling whose measured error is below ``tol``."""
    best: tuple[float, int, float] | None = None
    for p in (4, 6, 8, 10, 12, 14, 16, 20, 24):
        for s in (1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0):
            if lagrange_error(p, s) <= tol:
                cost = (5 * s + p) ** 2 + p * p  # grid nodes ~ (s W B / pi + 2 p)^2; targets ~ p^2
                if best is None or cost < best[0]:
                    best = (cost, p, s)
    if best is None:
        return 24, 6.0
    return best[1], best[2]
