"""The shapes the data leave open, removed from the map together.

Frame and units (docs/physics.md): aperture x, y and delta in m; each shape in m per unit of
its coefficient.

Two shapes can be unobservable at once: delta_c when the gain is estimated
(:mod:`solver.gainmode`) and the central mode when a feed cabin hides the middle of the
aperture (:mod:`solver.central`). Both are zero on the rim and fall monotonically towards it,
so over the observed annulus they are far from orthogonal (correlation about 0.9 on the
paper's dish). Removing them one after the other leaves the part of the first that the second
explains: the map and the truth then differ by a multiple of the second shape's remainder,
tens of micrometres for a scale error of 2e-5. A joint least-squares fit over the region where
the map is measured removes exactly the span of the shapes, whatever their overlap, and the
truth gets the identical projection before the RMS.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from solver.aperture import ApertureGrid


@dataclass(frozen=True)
class Unobservable:
    """Shapes removed jointly (``names`` beside ``shapes``, NaN outside the aperture) by least
    squares over ``region`` (a boolean mask on the aperture grid: where the map is measured)."""

    names: tuple[str, ...]
    shapes: tuple[NDArray[np.float64], ...]
    region: NDArray[np.bool_]

    def _support(self, grid: ApertureGrid) -> NDArray[np.bool_]:
        """Where the fit looks: the region, inside the aperture, where every shape is finite."""
        use = self.region & grid.mask
        for shape in self.shapes:
            use &= np.isfinite(shape)
        return use

    def remove(self, grid: ApertureGrid, delta: NDArray[np.float64]
               ) -> tuple[NDArray[np.float64], dict[str, float]]:
        """``delta`` (m) minus its joint least-squares fit by the shapes over the region, and
        each shape's coefficient. Shapes that vanish on the region get coefficient 0."""
        stack = np.stack([np.where(np.isfinite(s), s, 0.0) for s in self.shapes])
        use = self._support(grid) & np.isfinite(delta)
        design = stack[:, use].T
        if not use.any() or not np.any(design):
            return delta, dict.fromkeys(self.names, 0.0)
        coef, *_ = np.linalg.lstsq(design, delta[use], rcond=None)
        fitted = np.tensordot(coef, stack, axes=1)
        return delta - fitted, {n: float(c) for n, c in zip(self.names, coef, strict=True)}

    def correlation(self, grid: ApertureGrid) -> float:
        """The largest |cosine| between two of the shapes over the region (0 for one shape):
        near 1, the coefficients trade against each other and only their sum is meaningful."""
        use = self._support(grid)
        vectors = [s[use] / np.linalg.norm(s[use]) for s in self.shapes if np.any(s[use])]
        cosines = [abs(float(np.dot(u, v))) for k, u in enumerate(vectors) for v in vectors[k + 1:]]
        return max(cosines, default=0.0)

    def attrs(self, grid: ApertureGrid) -> dict[str, object]:
        """The SurfaceMap attributes of the joint removal."""
        return {"unobservable_modes": " ".join(self.names),
                "unobservable_fit": "one joint least-squares fit of the shapes where the map is "
                                    "measured, applied alike to the truth",
                "unobservable_correlation": self.correlation(grid)}


def unobservable(grid: ApertureGrid, named: dict[str, NDArray[np.float64] | None],
                 hole_radius: float | None = None) -> Unobservable | None:
    """The :class:`Unobservable` of the ``named`` shapes that are not None (None when none is),
    fitted where the map is measured: the aperture, less the hidden centre r < ``hole_radius``
    (m) when a cabin blocks it."""
    kept = {name: shape for name, shape in named.items() if shape is not None}
    if not kept:
        return None
    region = grid.mask.copy()
    if hole_radius is not None:
        region &= grid.r >= hole_radius
    return Unobservable(tuple(kept), tuple(kept.values()), region)
