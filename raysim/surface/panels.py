"""Ring layout of reflector panels in the aperture plane: ids, outlines, gaps, point location.

A dish of diameter D is cut into rings at radii ``ring_edges`` (m, from 0 or an inner hole
radius to D/2); ring i holds ``panels_per_ring[i]`` equal panels in azimuth, panel k of a ring
spanning phi in [phi0 + k dphi, phi0 + (k+1) dphi]. Neighbouring panels are separated by gaps
of constant width ``gap`` (m): straight strips of width ``gap`` along the radial cuts and
annular strips of width ``gap`` along the ring edges. The dish's outer rim stays at D/2 and a
ring with one panel has no radial cut. The frame is the aperture plane (x, y) of docs/physics.md,
phi = atan2(y, x). Panel ids run 0, 1, ... ring by ring, counter-clockwise.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclass(frozen=True)
class PanelLayout:
    """Ring layout (all lengths in metres, angles in radians)."""

    ring_edges: tuple[float, ...]
    panels_per_ring: tuple[int, ...]
    gap: float = 0.0
    phi0: float = 0.0
    _ring_of: NDArray[np.int64] = field(init=False, repr=False, compare=False)
    _centres: NDArray[np.float64] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        edges = np.asarray(self.ring_edges, dtype=np.float64)
        if edges.ndim != 1 or len(edges) < 2 or np.any(np.diff(edges) <= 0) or edges[0] < 0:
            raise ValueError("ring_edges must rise strictly from >= 0")
        if len(self.panels_per_ring) != len(edges) - 1:
            raise ValueError("panels_per_ring needs one count per ring (len(ring_edges) - 1)")
        if any(int(n) < 1 for n in self.panels_per_ring):
            raise ValueError("panels_per_ring counts must be >= 1")
        if self.gap < 0:
            raise ValueError("gap must be >= 0")
        ring_of = np.repeat(np.arange(self.n_rings), np.asarray(self.panels_per_ring, dtype=int))
        object.__setattr__(self, "_ring_of", ring_of)
        object.__setattr__(self, "_centres", self._sector_centroids())

    # --- the table of panels -------------------------------------------------------------
    @property
    def n_rings(self) -> int:
        return len(self.ring_edges) - 1

    @property
    def n_panels(self) -> int:
        return int(sum(self.panels_per_ring))

    @property
    def rim_radius(self) -> float:
        return float(self.ring_edges[-1])

    def ring(self, panel: ArrayLike) -> NDArray[np.int64]:
        """Ring index of each panel id."""
        return self._ring_of[np.asarray(panel, dtype=np.int64)]

    def first_panel(self, ring: int) -> int:
        return int(sum(self.panels_per_ring[:ring]))

    def dphi(self, ring: int) -> float:
        return 2.0 * np.pi / self.panels_per_ring[ring]

    def radial_limits(self, ring: int) -> tuple[float, float]:
        """Inner and outer radius (m) of the panels of ``ring``, gaps taken off."""
        half = 0.5 * self.gap
        lo = self.ring_edges[ring] + (half if ring > 0 else 0.0)
        hi = self.ring_edges[ring + 1] - (half if ring < self.n_rings - 1 else 0.0)
        if self.panels_per_ring[ring] > 1 and self.gap > 0:
            # the two gap strips of a wedge meet at this radius: nothing lies inside it
            lo = max(lo, half / np.sin(0.5 * self.dphi(ring)))
        return float(lo), float(hi)

    def angular_limits(self, panel: int) -> tuple[float, float]:
        """phi range (rad) of the cut lines bounding ``panel`` (gaps not taken off)."""
        ring = int(self.ring(panel))
        k = panel - self.first_panel(ring)
        d = self.dphi(ring)
        return self.phi0 + k * d, self.phi0 + (k + 1) * d

    def centres(self) -> NDArray[np.float64]:
        """Area centroids (x, y) of the panels' annular sectors (m), shape (n_panels, 2)."""
        return self._centres

    def _sector_centroids(self) -> NDArray[np.float64]:
        out = np.empty((self.n_panels, 2))
        for p in range(self.n_panels):
            ring = int(self.ring(p))
            a, b = self.ring_edges[ring], self.ring_edges[ring + 1]
            phi_a, phi_b = self.angular_limits(p)
            half = 0.5 * (phi_b - phi_a)
            if self.panels_per_ring[ring] == 1:
                out[p] = 0.0
                continue
            r_c = (2.0 / 3.0) * (b**3 - a**3) / (b**2 - a**2) * np.sin(half) / half
            mid = 0.5 * (phi_a + phi_b)
            out[p] = r_c * np.cos(mid), r_c * np.sin(mid)
        return out

    # --- point location --------------------------------------------------------------------
    def panel_at(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.int64]:
        """Panel id under each aperture point (x, y) (m); -1 in a gap or outside the dish."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        r = np.hypot(x, y)
        phi = np.mod(np.arctan2(y, x) - self.phi0, 2.0 * np.pi)
        out = np.full(r.shape, -1, dtype=np.int64)
        for ring in range(self.n_rings):
            lo, hi = self.radial_limits(ring)
            inside = (r >= lo) & (r <= hi)
            if not np.any(inside):
                continue
            n = self.panels_per_ring[ring]
            d = 2.0 * np.pi / n
            k = np.minimum((phi[inside] / d).astype(np.int64), n - 1)
            if n > 1 and self.gap > 0:
                # distance to the two radial cut lines must be at least gap / 2
                rr = r[inside]
                to_lo = rr * np.sin(phi[inside] - k * d)
                to_hi = rr * np.sin((k + 1) * d - phi[inside])
                ok = (to_lo >= 0.5 * self.gap) & (to_hi >= 0.5 * self.gap)
            else:
                ok = np.ones(k.shape, dtype=bool)
            ids = np.where(ok, self.first_panel(ring) + k, -1)
            out[inside] = ids
        return out

    def lateral_limits(self, panel: int, r: ArrayLike) -> tuple[NDArray, NDArray]:
        """phi range (rad) of ``panel`` at radius r (m): the gap strips' edges at that radius.

        The strip edge is the line at distance gap/2 from the cut, so its angle from the cut
        is asin(gap / (2 r)).
        """
        r = np.asarray(r, dtype=np.float64)
        phi_a, phi_b = self.angular_limits(panel)
        ring = int(self.ring(panel))
        if self.panels_per_ring[ring] == 1 or self.gap == 0:
            return np.full(r.shape, phi_a), np.full(r.shape, phi_b)
        off = np.arcsin(np.clip(0.5 * self.gap / np.maximum(r, 1e-300), 0.0, 1.0))
        return phi_a + off, phi_b - off

    def gap_area(self) -> float:
        """Exact aperture area (m^2) of the gaps inside the rim (the dish area minus panels)."""
        return float(np.pi * self.rim_radius**2 - sum(self.panel_area(p) for p in range(self.n_panels)))

    def panel_area(self, panel: int) -> float:
        """Exact area (m^2) of one panel's footprint in the aperture plane."""
        ring = int(self.ring(panel))
        lo, hi = self.radial_limits(ring)
        if hi <= lo:
            return 0.0
        n = self.panels_per_ring[ring]
        if n == 1 or self.gap == 0:
            return (hi**2 - lo**2) * np.pi / n
        # area between radii lo..hi and between the two lines at distance g/2 from the cuts:
        # integral of r * (dphi - 2 asin(g / 2r)) dr
        g2 = 0.5 * self.gap
        d = self.dphi(ring)

        def primitive(r: float) -> float:
            # d/dr [r^2/2 asin(c/r) + c/2 sqrt(r^2 - c^2)] = r asin(c/r)
            return 0.5 * r * r * np.arcsin(g2 / r) + 0.5 * g2 * np.sqrt(max(r * r - g2 * g2, 0.0))

        return float(0.5 * d * (hi**2 - lo**2) - 2.0 * (primitive(hi) - primitive(lo)))
