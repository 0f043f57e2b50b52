"""Samples a leaf cluster's field needs: on the level's whole-sphere grid, or on a cone of its own.

Run: ``python benchmarks/bench_leaf_charts.py [--frequency 3] [--tol 1e-7]``.

The fast radiator's leaf step evaluates every element at every node of its cluster's grid, so
its cost is N x (nodes per leaf). Today's grids (:mod:`raysim.optics.fast.chart`) cover the
double-covered torus of the target sphere's angles, the whole sphere, whatever part of it the
targets occupy. The alternative that the interpolation literature offers (IFGF, Bauinger and
Bruno, J. Comput. Phys. 430, 2021) samples each cluster's field on a cone segment of its own:
a Chebyshev tensor grid in the two direction cosines across the cone from the cluster's centre
c to the sphere's centre and in s = R / |P - c|, over the box that holds the targets. This
measures, before anything is built, how many nodes each needs for the same accuracy.

Scene: the paper's dish (F = 33 m), targets on the hemisphere theta <= 90 deg of the sphere of
radius 10 m about the focus, leaf clusters of 8 elements with random complex moments placed
at random within radius a on the paraboloid near its vertex, half way out and at the rim. The
field is the electric element's (Balanis, *Advanced Engineering Electromagnetics*, ch. 6),
written here in numpy, with the centre's phase exp(-j k |P - c|) taken out as both charts do.

- torus: the least degree L whose Fourier tail (|frequency| >= L along either angle) holds
  under ``tol`` of the whole (Parseval: the RMS error of truncating there), the grid
  ``size_for(L - 1)`` and its computed rows ``half_rows(n) * n``;
- cone: the fewest m x m x m_s Chebyshev nodes whose tensor interpolation of the field on the
  targets (a 1 x 1 degree grid of the hemisphere) is within ``tol`` relative RMS.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from raysim.constants import C0  # noqa: E402
from raysim.maps.sphere import SphereGrid  # noqa: E402
from raysim.optics.fast.chart import Domain, grid_points, half_rows, size_for  # noqa: E402

FOCAL, RADIUS = 33.0, 10.0
CENTRE = np.array([0.0, 0.0, FOCAL])
PLACES = {"vertex": (1.0, 0.5), "half way": (30.0, 5.0), "rim": (53.0, 8.0)}


def surface(x: NDArray, y: NDArray) -> NDArray:
    """Points of the paraboloid z = (x^2 + y^2) / 4F (m)."""
    return np.stack([x, y, (x * x + y * y) / (4.0 * FOCAL)], axis=-1)


def cluster(rng: np.random.Generator, x0: float, y0: float, a: float) -> tuple[NDArray, NDArray, NDArray]:
    """8 element positions within radius ``a`` of (x0, y0) on the dish, their moments, the centre."""
    angle, r = rng.uniform(0.0, 2.0 * np.pi, 8), a * np.sqrt(rng.uniform(0.0, 1.0, 8))
    S = surface(x0 + r * np.cos(angle), y0 + r * np.sin(angle))
    p = rng.normal(size=(8, 3)) + 1j * rng.normal(size=(8, 3))
    return S, p, surface(np.array(x0), np.array(y0))


def field(P: NDArray, S: NDArray, p: NDArray, c: NDArray, k: float) -> NDArray:
    """Sum over the elements of exp(-jkR)/R [a p - b (R_hat . p) R_hat], times exp(+jk|P - c|)."""
    d = P[:, None, :] - S[None]
    R = np.linalg.norm(d, axis=-1)
    Rh = d / R[..., None]
    u = 1.0 / (k * R)
    a, b = 1 - 1j * u - u * u, 1 - 3j * u - 3 * u * u
    bracket = a[..., None] * p[None] - (b * np.einsum("msi,si->ms", Rh, p))[..., None] * Rh
    E = (np.exp(-1j * k * R) / R)[..., None] * bracket
    return E.sum(axis=1) * np.exp(1j * k * np.linalg.norm(P - c, axis=1))[:, None]


def torus_nodes(S: NDArray, p: NDArray, c: NDArray, k: float, tol: float, n: int = 256) -> tuple[int, int]:
    """(L, computed nodes) of the whole-sphere grid that holds the field to ``tol``."""
    torus = grid_points(n, Domain(tuple(CENTRE), RADIUS, n * n))  # the fast radiator's own grid
    G = field(torus, S, p, c, k).reshape(n, n, 3)
    power = (np.abs(np.fft.fft2(G, axes=(0, 1))) ** 2).sum(axis=-1)
    f = np.abs(np.fft.fftfreq(n, 1.0 / n))
    band = np.maximum(f[:, None], f[None, :])
    total = power.sum()
    for L in range(1, n // 2):
        if math.sqrt(power[band >= L].sum() / total) < tol:
            m = size_for(L - 1)
            return L, half_rows(m) * m
    raise RuntimeError("the field is not resolved on the reference grid")


def chebyshev(m: int, lo: float, hi: float) -> NDArray:
    """The m Chebyshev points of the first kind on [lo, hi]."""
    return lo + (hi - lo) * (1.0 - np.cos(np.pi * (np.arange(m) + 0.5) / m)) / 2.0


def lagrange_weights(nodes: NDArray, x: NDArray) -> NDArray:
    """(len(x), len(nodes)) barycentric Lagrange weights."""
    w = np.array([1.0 / np.prod(np.delete(nodes[i] - nodes, i)) for i in range(len(nodes))])
    D = x[:, None] - nodes[None]
    D[D == 0.0] = 1e-300
    W = w[None] / D
    return W / W.sum(axis=1, keepdims=True)


def cone_nodes(S: NDArray, p: NDArray, c: NDArray, k: float, tol: float) -> tuple[int, int, int]:
    """(m, m_s, m * m * m_s): the fewest cone-segment Chebyshev nodes holding the field to ``tol``."""
    P = SphereGrid(RADIUS, 90, 360).points(FOCAL).reshape(-1, 3)  # the paper's targets
    axis = (CENTRE - c) / np.linalg.norm(CENTRE - c)
    e1 = np.cross(axis, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    d = P - c
    dist = np.linalg.norm(d, axis=1)
    X, Y, s = d @ e1 / dist, d @ e2 / dist, RADIUS / dist
    box = [(v.min(), v.max()) for v in (X, Y, s)]
    truth = field(P, S, p, c, k)
    scale = math.sqrt((np.abs(truth) ** 2).sum() / len(P))
    best: tuple[int, int, int] | None = None
    for m in range(4, 25):
        for ms in range(1, 8):
            if best is not None and m * m * ms >= best[2]:
                continue
            xs, ys = chebyshev(m, *box[0]), chebyshev(m, *box[1])
            ss = chebyshev(ms, *box[2]) if ms > 1 else np.array([np.mean(box[2])])
            XX, YY, SS = np.meshgrid(xs, ys, ss, indexing="ij")
            ZZ = np.sqrt(np.maximum(1.0 - XX**2 - YY**2, 0.0))
            ray = XX[..., None] * e1 + YY[..., None] * e2 + ZZ[..., None] * axis  # unit directions
            Q = c + (RADIUS / SS)[..., None] * ray
            V = field(Q.reshape(-1, 3), S, p, c, k).reshape(m, m, ms, 3)
            Ls = lagrange_weights(ss, s) if ms > 1 else np.ones((len(s), 1))
            approx = np.einsum("ni,nj,nk,ijkc->nc", lagrange_weights(xs, X), lagrange_weights(ys, Y), Ls, V)
            if math.sqrt((np.abs(approx - truth) ** 2).sum() / len(P)) / scale < tol:
                best = (m, ms, m * m * ms)
    if best is None:
        raise RuntimeError("no cone grid up to 24 x 24 x 7 holds the field")
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frequency", type=float, default=3.0, help="GHz")
    parser.add_argument("--tol", type=float, default=1e-7, help="relative RMS (one step's share of 1e-6)")
    parser.add_argument("--radii", type=float, nargs="+", default=[0.7, 1.5, 3.0],
                        help="cluster radii (wavelengths)")
    args = parser.parse_args()
    k = 2.0 * np.pi * args.frequency * 1e9 / C0
    wavelength = 2.0 * np.pi / k
    rng = np.random.default_rng(1)
    print(f"{args.frequency:g} GHz, tolerance {args.tol:g}\n")
    print("| cluster | radius (wavelengths) | torus L | torus nodes | cone m x m x m_s | cone nodes "
          "| ratio |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for name, (x0, y0) in PLACES.items():
        for a in args.radii:
            S, p, c = cluster(rng, x0, y0, a * wavelength)
            L, torus = torus_nodes(S, p, c, k, args.tol)
            m, ms, cone = cone_nodes(S, p, c, k, args.tol)
            print(f"| {name} | {a:g} | {L} | {torus} | {m} x {m} x {ms} | {cone} | {torus / cone:.1f} |",
                  flush=True)


if __name__ == "__main__":
    main()
