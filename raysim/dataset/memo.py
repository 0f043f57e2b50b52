"""A deformation that remembers its last evaluation, for traces that ask at the same points.

A GO trace evaluates delta(x, y) and its gradient at the mesh vertices to displace them,
then again at every Newton step that puts the hits on the smooth surface and once more for
the normals. For a wave on axis the rays run along z, so every one of those calls asks at the
very same (x, y). :class:`Memo` answers a repeated question from its last answer (same
values bit for bit) and computes anything new as the wrapped deformation does.

Across the samples of a dataset those points are always the ideal mesh's vertices.
:class:`VertexFactors` keeps, once per process, what a deformation's value there does not
owe to the sample: each Zernike term's radial and angular factors and its gradient's brackets
(:meth:`raysim.dataset.zernike.ZernikeSeries.factors`). A Memo given them evaluates value and
gradient together at those points, from the factors, in the same floating-point operations
and order as the plain evaluation, so the numbers are the same bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from raysim.dataset.models import RimAstigmatism
from raysim.dataset.zernike import Factors, ZernikeSeries
from raysim.surface.deformation import (
    Deformation,
    GaussianBumps,
    NoDeformation,
    PaperDeformation,
    Sum,
    Zernike,
)

FACTOR_BUDGET = 1 << 30  # bytes of Zernike factors one process keeps at most


def _same(a: Any, b: Any) -> bool:
    if a is None or b is None:
        return a is None and b is None
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and bool(np.array_equal(a, b))


class VertexFactors:
    """Sample-independent factors of deformations at one fixed set of aperture points (m).

    Factors are made from the arrays of the first call that asks at these points (a caller
    passes the same kind of arrays every time: views of a mesh's vertices) and kept while
    they fit ``budget`` bytes; beyond it a deformation is evaluated as usual.
    """

    def __init__(self, x: Any, y: Any, budget: int = FACTOR_BUDGET) -> None:
        self.x = np.array(x, dtype=np.float64, copy=True)
        self.y = np.array(y, dtype=np.float64, copy=True)
        self.budget = int(budget)
        self._kept: dict[tuple, Any] = {}
        self.nbytes = 0

    def at(self, x: Any, y: Any) -> bool:
        """Whether (x, y) are these points."""
        return _same(x, self.x) and _same(y, self.y)

    def _get(self, key: tuple, arrays: int, make: Callable[[], Any]) -> Any:
        """The factors under ``key`` (``arrays`` arrays of these points' size), or None when
        they would not fit the budget."""
        if key not in self._kept:
            need = arrays * self.x.size * 8
            fits = self.nbytes + need <= self.budget
            self._kept[key] = make() if fits else None
            self.nbytes += need if fits else 0
        return self._kept[key]

    def zernike(self, series: ZernikeSeries, x: Any, y: Any) -> list[Factors] | None:
        """The factors of ``series``'s terms at these points (x, y), or None over budget."""
        key = ("zernike", tuple((n, m) for n, m, _ in series.terms), float(series.radius))
        # R and the two brackets per term; the angular factors are shared by the terms
        return self._get(key, 3 * len(series.terms), lambda: list(series.factors(x, y, gradient=True)))

    def rim(self, rim: RimAstigmatism, x: Any, y: Any) -> tuple | None:
        """(phi, rho, cos phi, sin phi) of a rim astigmatism of this radius at these points."""
        return self._get(("rim", float(rim.radius)), 4, lambda: rim.geometry(x, y))


# kinds whose values ignore the panel argument (exact types: a subclass may not)
_PANEL_FREE = (NoDeformation, ZernikeSeries, GaussianBumps, RimAstigmatism, PaperDeformation, Zernike)


def panel_free(deformation: Deformation) -> bool:
    """Whether ``deformation``'s values are known not to depend on the panel ids passed."""
    if type(deformation) is Sum:
        return all(panel_free(part) for part in deformation.parts)
    return type(deformation) in _PANEL_FREE


def value_and_gradient(deformation: Deformation, x: Any, y: Any, panel: Any,
                       factors: VertexFactors) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """(delta, (d/dx, d/dy)) at the points of ``factors``, bit for bit as the deformation's
    own ``__call__`` and ``gradient`` give them (a :class:`Sum` adds its parts in its order)."""
    if type(deformation) is ZernikeSeries:
        terms = factors.zernike(deformation, x, y)
        if terms is not None:
            value, gx, gy = deformation.evaluate(x, y, True, terms)
            return value, (gx, gy)
    if type(deformation) is RimAstigmatism:
        geometry = factors.rim(deformation, x, y)
        if geometry is not None:
            value, gx, gy = deformation.evaluate(x, y, True, geometry)
            return value, (gx, gy)
    if type(deformation) is GaussianBumps:  # its one pass gives value and slopes together
        value, gx, gy = deformation._eval(x, y)
        return value, (gx, gy)
    if type(deformation) is Sum:
        value = np.zeros(np.broadcast(np.asarray(x), np.asarray(y)).shape)
        gx = np.zeros(value.shape)
        gy = np.zeros_like(gx)
        for part in deformation.parts:
            v, (px, py) = value_and_gradient(part, x, y, panel, factors)
            value = value + v
            gx, gy = gx + px, gy + py
        return value, (gx, gy)
    return deformation(x, y, panel), deformation.gradient(x, y, panel)


@dataclass(eq=False)
class Memo(Deformation):
    """``inner`` (any deformation, metres) with its last value and last gradient kept.

    With ``factors``, a question at their points computes value and gradient at once from them.
    For a deformation that ignores panel ids (:func:`panel_free`), questions that differ
    only in the panel ids passed are the same question.
    """

    inner: Deformation
    factors: VertexFactors | None = None
    _value: tuple | None = field(default=None, repr=False)
    _gradient: tuple | None = field(default=None, repr=False)
    _panel_free: bool = field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
        self._panel_free = panel_free(self.inner)

    @staticmethod
    def _key(x, y, panel) -> tuple:
        return tuple(None if v is None else np.array(v, copy=True) for v in (x, y, panel))

    def _hit(self, cached: tuple | None, x, y, panel) -> bool:
        return (cached is not None and _same(cached[0], x) and _same(cached[1], y)
                and (self._panel_free or _same(cached[2], panel)))

    def _both(self, x, y, panel) -> bool:
        """Fill value and gradient from the factors when (x, y) are their points."""
        if self.factors is None or not self.factors.at(x, y):
            return False
        value, gradient = value_and_gradient(self.inner, x, y, panel, self.factors)
        key = self._key(x, y, panel)
        self._value, self._gradient = (*key, value), (*key, gradient)
        return True

    def __call__(self, x, y, panel=None):
        if not self._hit(self._value, x, y, panel) and not self._both(x, y, panel):
            self._value = (*self._key(x, y, panel), self.inner(x, y, panel))
        return self._value[3].copy()

    def gradient(self, x, y, panel=None):
        if not self._hit(self._gradient, x, y, panel) and not self._both(x, y, panel):
            self._gradient = (*self._key(x, y, panel), self.inner.gradient(x, y, panel))
        gx, gy = self._gradient[3]
        return gx.copy(), gy.copy()

    def describe(self) -> str:
        return self.inner.describe()
