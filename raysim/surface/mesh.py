"""Reflector meshes: the ideal paraboloid, its deformed twin, panels with gaps, loaded files.

Frame (docs/physics.md): vertex at the origin, axis +z, focus (0, 0, F), metres. A generated mesh is
laid out in the aperture plane panel by panel (rows of constant radius, about ``resolution``
apart, triangulated strip by strip) and lifted onto the surface z = r^2/(4F) + delta(x, y).
The deformed mesh is the ideal one with every vertex moved along z, so both share one
triangulation and the facets' own errors cancel in the intensity ratio. Panels own their
vertices: nothing is shared, averaged or triangulated across a gap.

Ray hits and normals are taken on the reflector's smooth surface (``Reflector.surface``), not
on the flat facets (a facet of size h sags h^2/(16F) below it). For a mesh loaded from a file
that surface is the fitted paraboloid plus the mesh's own departure from it, interpolated
smoothly over each connected piece (:mod:`raysim.surface.departure`); its ideal counterpart
is the paraboloid itself (or the ideal file's departure), on the same triangulation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from raysim.errors import MeshError, SceneError
from raysim.surface.deformation import Deformation, NoDeformation
from raysim.surface.obstacles import ObstacleMesh, obstacle_mesh
from raysim.surface.panels import PanelLayout


@dataclass(frozen=True)
class ParaboloidSurface:
    """The smooth surface z = (x^2 + y^2)/(4F) + d(x, y) + delta(x, y, panel), metres.

    ``departure`` d is a loaded mesh's own departure from its fitted paraboloid
    (:class:`raysim.surface.departure.MeshDeparture`), None for raysim's own dishes. With it,
    ``panel`` holds the mesh's faces the points lie on, which are d's to use; ``deformation``
    (a scene's, on top of the mesh) takes each face's panel of the scene's layout from
    ``face_layout_panel`` (None: it finds them from (x, y)).
    """

    F: float
    deformation: Deformation = field(default_factory=NoDeformation)
    departure: Deformation | None = None
    # an array: left out of the dataclass's equality and hash (both stay defined)
    face_layout_panel: NDArray[np.int64] | None = field(default=None, compare=False)

    def _deformation_panel(self, panel: ArrayLike | None) -> ArrayLike | None:
        """The ``panel`` ids the deformation takes for the surface's ``panel``."""
        if self.departure is None:
            return panel
        if self.face_layout_panel is None or panel is None:
            return None
        return self.face_layout_panel[np.asarray(panel, dtype=np.int64)]

    def height(self, x: ArrayLike, y: ArrayLike, panel: ArrayLike | None = None) -> NDArray:
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        z = (x * x + y * y) / (4.0 * self.F)
        if self.departure is None:
            return z + self.deformation(x, y, panel)
        return z + self.departure(x, y, panel) + self.deformation(x, y, self._deformation_panel(panel))

    def slope(self, x: ArrayLike, y: ArrayLike, panel: ArrayLike | None = None) -> tuple[NDArray, NDArray]:
        """(dz/dx, dz/dy) of the surface, dimensionless."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        gx, gy = self.added_slope(x, y, panel)
        return x / (2.0 * self.F) + gx, y / (2.0 * self.F) + gy

    def added(self, x: ArrayLike, y: ArrayLike, panel: ArrayLike | None = None) -> NDArray:
        """What the surface adds to its paraboloid at (x, y) (m, along z): the departure and the
        deformation."""
        if self.departure is None:
            return self.deformation(x, y, panel)
        return self.departure(x, y, panel) + self.deformation(x, y, self._deformation_panel(panel))

    def added_slope(self, x: ArrayLike, y: ArrayLike,
                    panel: ArrayLike | None = None) -> tuple[NDArray, NDArray]:
        """The slope (d/dx, d/dy, dimensionless) of what the surface adds to its paraboloid."""
        if self.departure is None:
            return self.deformation.gradient(x, y, panel)
        dx, dy = self.departure.gradient(x, y, panel)
        ex, ey = self.deformation.gradient(x, y, self._deformation_panel(panel))
        return dx + ex, dy + ey

    def normal(self, x: ArrayLike, y: ArrayLike, panel: ArrayLike | None = None) -> NDArray:
        """Unit normals pointing into the dish (towards +z), shape (..., 3)."""
        return unit_normals(*self.slope(x, y, panel))


def unit_normals(gx: ArrayLike, gy: ArrayLike) -> NDArray[np.float64]:
    """(-gx, -gy, 1) / |(-gx, -gy, 1)|, shape (..., 3): the unit normals of slopes (gx, gy).

    Component by component, in the operations of ``np.linalg.norm`` over the stacked rows
    (the squares summed left to right, then 1 * 1) and their order, so the same bits as
    ``n / np.linalg.norm(n, axis=-1, keepdims=True)`` of ``n = np.stack([-gx, -gy, 1])``,
    without its (..., 3) temporaries: 4x faster on a paper-grid mesh, where every GO sample
    takes two sets of normals.
    """
    ngx = np.negative(np.asarray(gx, dtype=np.float64))
    ngy = np.negative(np.asarray(gy, dtype=np.float64))
    norm = np.sqrt(ngx * ngx + ngy * ngy + 1.0)
    n = np.empty((*np.broadcast(ngx, ngy).shape, 3))
    np.divide(ngx, norm, out=n[..., 0])
    np.divide(ngy, norm, out=n[..., 1])
    np.divide(1.0, norm, out=n[..., 2])
    return n


@dataclass(frozen=True, eq=False)
class Reflector:
    """A triangulated reflector with float64 vertices and per-face panel ids.

    ``vertex_normals`` are unit normals towards +z, smooth within a panel. ``surface`` is the
    smooth surface hits belong on (for a loaded mesh, its fitted paraboloid plus its
    departure), or None for a bare triangulation (hits on the facets).
    ``obstacles``: what stands in the beam (:mod:`raysim.surface.obstacles`), shared by the
    deformed twin; None for a clear aperture.
    """

    vertices: NDArray[np.float64]
    faces: NDArray[np.int64]
    face_panel: NDArray[np.int64]
    vertex_normals: NDArray[np.float64]
    F: float
    D: float
    surface: ParaboloidSurface | None = None
    layout: PanelLayout | None = None
    obstacles: ObstacleMesh | None = None

    def with_obstacles(self, obstacles: ObstacleMesh | None) -> Reflector:
        """This reflector with ``obstacles`` in its beam (None: a clear aperture)."""
        return replace(self, obstacles=obstacles)

    @cached_property
    def vertex_panel(self) -> NDArray[np.int64]:
        out = np.full(len(self.vertices), -1, dtype=np.int64)
        out[self.faces.ravel()] = np.repeat(self.face_panel, 3)
        return out

    @cached_property
    def mesh(self):
        """The trimesh view of this reflector (for file export, queries and rendering)."""
        import trimesh

        return trimesh.Trimesh(self.vertices, self.faces, vertex_normals=self.vertex_normals,
                               face_attributes={"panel": self.face_panel}, process=False)

    @property
    def from_file(self) -> bool:
        """A mesh loaded from a file: its surface holds the mesh's own departure."""
        return getattr(self.surface, "departure", None) is not None

    @property
    def arc_edges(self) -> bool:
        """Free edges whose two ends lie at one radius are arcs of that circle (raysim's own
        layouts lay panel rows on circles); a file's edges stay the straight segments it has."""
        return self.surface is not None and not self.from_file

    def surface_panel(self, face: NDArray[np.int64]) -> NDArray[np.int64] | None:
        """What the smooth surface takes as ``panel`` for points on faces ``face``: a loaded
        mesh's faces themselves (its departure is blended over each), the layout's panels,
        None for a one-piece generated dish."""
        if self.from_file:
            return np.asarray(face, dtype=np.int64)
        return self.face_panel[face] if self.layout is not None else None

    @cached_property
    def face_surface_panel(self) -> NDArray[np.int64]:
        """Per face, the ids a ray lattice carries for the smooth surface (every lattice point
        of a face takes its face's): a loaded mesh's faces, else the faces' panels."""
        return np.arange(len(self.faces)) if self.from_file else self.face_panel

    @cached_property
    def vertex_surface_panel(self) -> NDArray[np.int64]:
        """What the smooth surface takes as ``panel`` at the vertices (as
        :meth:`surface_panel`; for a loaded mesh a face holding each vertex)."""
        if self.from_file:
            from raysim.surface.departure import vertex_faces

            return vertex_faces(self.faces, len(self.vertices))
        return self.vertex_panel

    @property
    def n_panels(self) -> int:
        return int(self.face_panel.max()) + 1 if len(self.face_panel) else 0

    def projected_area(self, direction: ArrayLike = (0.0, 0.0, -1.0)) -> float:
        """Area (m^2) of the mesh seen along ``direction``: the aperture a plane wave lights."""
        d = np.asarray(direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        v = self.vertices[self.faces]
        cross = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        return float(0.5 * np.sum(np.abs(cross @ d)))

    def deformed(self, deformation: Deformation) -> Reflector:
        """This reflector with every vertex moved by delta(x, y) along z (same triangulation)."""
        x, y = self.vertices[:, 0], self.vertices[:, 1]
        panel = self._panel_for_deformation()
        vertices = self.vertices.copy()
        vertices[:, 2] += deformation(x, y, panel)
        if self.surface is not None:
            surface = replace(self.surface, deformation=self.surface.deformation + deformation
                              if not isinstance(self.surface.deformation, NoDeformation)
                              else deformation)
            normals = surface.normal(x, y, self.vertex_surface_panel if self.from_file else panel)
        else:
            surface = None
            normals = facet_vertex_normals(vertices, self.faces)
        return Reflector(vertices, self.faces, self.face_panel, normals, self.F, self.D, surface,
                         self.layout, self.obstacles)

    def _panel_for_deformation(self) -> NDArray[np.int64] | None:
        # scene panel ids only mean something for deformations when the layout made the mesh,
        # or a loaded mesh's pieces were matched to the scene's layout (with_layout_panels)
        if self.from_file:
            return self.surface._deformation_panel(self.vertex_surface_panel)
        return self.vertex_panel if self.layout is not None else None

    def with_layout_panels(self, layout: PanelLayout | None) -> Reflector:
        """This loaded mesh with each connected piece matched to the panel of ``layout`` that
        holds most of its faces' centroids, for a scene's panel deformations (their panel ids
        at a panel's own edge vertex, looked up from (x, y), fell in the gap: 716 of 4554
        vertices kept no panel error). A piece in no panel gets -1 (a gap)."""
        if layout is None or not self.from_file:
            return self
        v, f = self.vertices, self.faces
        centroid = (v[f[:, 0]] + v[f[:, 1]] + v[f[:, 2]]) / 3.0
        found = np.asarray(layout.panel_at(centroid[:, 0], centroid[:, 1]), dtype=np.int64)
        piece_panel = np.full(self.n_panels, -1, dtype=np.int64)
        for piece in range(self.n_panels):
            votes = found[(self.face_panel == piece) & (found >= 0)]
            if len(votes):
                piece_panel[piece] = int(np.bincount(votes).argmax())
        surface = replace(self.surface, face_layout_panel=piece_panel[self.face_panel])
        return replace(self, surface=surface)


# --- generated meshes ------------------------------------------------------------------------
def paraboloid(D: float, F: float, resolution: float = 0.15,
               layout: PanelLayout | None = None) -> Reflector:
    """The ideal paraboloid z = r^2/(4F) of diameter D (m), as panels of ``layout`` or one piece.

    ``resolution`` (m) is the target triangle edge in the aperture plane.
    """
    if layout is None:
        layout = PanelLayout((0.0, 0.5 * D), (1,), 0.0)
        panel_layout = None
    else:
        panel_layout = layout
    xy_parts, face_parts, panel_parts = [], [], []
    offset = 0
    for p in range(layout.n_panels):
        xy, faces = panel_footprint(layout, p, resolution)
        xy_parts.append(xy)
        face_parts.append(faces + offset)
        panel_parts.append(np.full(len(faces), p, dtype=np.int64))
        offset += len(xy)
    xy = np.concatenate(xy_parts)
    faces = np.concatenate(face_parts)
    surface = ParaboloidSurface(F)
    z = surface.height(xy[:, 0], xy[:, 1])
    vertices = np.column_stack([xy, z])
    normals = surface.normal(xy[:, 0], xy[:, 1])
    return Reflector(vertices, faces, np.concatenate(panel_parts), normals, float(F), float(D),
                     surface, panel_layout)


def panel_footprint(layout: PanelLayout, panel: int, h: float) -> tuple[NDArray, NDArray]:
    """Triangulate one panel's footprint in the aperture plane: (xy (n, 2), faces (m, 3)).

    Rows of constant radius about ``h`` apart; on each row points about ``h`` apart between
    the panel's gap edges (or all round for a one-panel ring); neighbouring rows joined by a
    strip of triangles. The straight gap edges are met exactly, arcs by chords. Faces are
    counter-clockwise seen from +z.
    """
    ring = int(layout.ring(panel))
    lo, hi = layout.radial_limits(ring)
    n_rows = max(1, int(np.ceil((hi - lo) / h)))
    radii = np.linspace(lo, hi, n_rows + 1)
    closed = layout.panels_per_ring[ring] == 1
    rows: list[NDArray] = []
    params: list[NDArray] = []
    for r in radii:
        if closed:
            if r <= 0.0:
                rows.append(np.zeros((1, 2)))
                params.append(np.array([0.0]))
                continue
            n = max(6, int(np.ceil(2.0 * np.pi * r / h)))
            t = np.arange(n) / n
            phi = layout.phi0 + 2.0 * np.pi * t
        else:
            phi_a, phi_b = layout.lateral_limits(panel, np.array([max(r, 1e-12)]))
            width = max(float(phi_b[0] - phi_a[0]), 0.0)
            n = max(1, int(np.ceil(r * width / h)))
            # the tip of a wedge, where the two gap edges meet, is a single point
            t = np.linspace(0.0, 1.0, n + 1) if r * width > 1e-9 else np.array([0.5])
            phi = phi_a[0] + t * width
        rows.append(np.column_stack([r * np.cos(phi), r * np.sin(phi)]))
        params.append(t)
    xy = np.concatenate(rows)
    starts = np.cumsum([0] + [len(r) for r in rows])
    faces = [
        _strip(starts[k], params[k], starts[k + 1], params[k + 1], closed)
        for k in range(len(rows) - 1)
    ]
    faces_arr = np.concatenate(faces) if faces else np.zeros((0, 3), dtype=np.int64)
    faces_arr = _counter_clockwise(xy, faces_arr)
    used = np.zeros(len(xy), dtype=bool)
    used[faces_arr.ravel()] = True
    renumber = np.cumsum(used) - 1
    return xy[used], renumber[faces_arr]


def _strip(a0: int, ta: NDArray, b0: int, tb: NDArray, closed: bool) -> NDArray[np.int64]:
    """Triangles joining row A (indices a0.., parameters ta) to row B (b0.., tb).

    Walking both rows in parameter order, each step advances along the row whose next point
    comes first and closes one triangle. Closed rows wrap to their first point.
    """
    na, nb = len(ta), len(tb)
    if closed:
        ia = np.append(np.arange(na), 0)
        ib = np.append(np.arange(nb), 0)
        ka = np.append(ta, 1.0) if na > 1 else np.array([0.0])
        kb = np.append(tb, 1.0) if nb > 1 else np.array([0.0])
    else:
        ia, ib, ka, kb = np.arange(na), np.arange(nb), ta, tb
    # events: advancing A to its point s (s >= 1) at key ka[s], or B likewise
    keys = np.concatenate([ka[1:], kb[1:]])
    is_a = np.concatenate([np.ones(len(ka) - 1, bool), np.zeros(len(kb) - 1, bool)])
    order = np.argsort(keys, kind="stable")
    is_a = is_a[order]
    i_now = np.cumsum(is_a) - is_a
    j_now = np.cumsum(~is_a) - ~is_a
    a_cur = a0 + ia[i_now]
    b_cur = b0 + ib[j_now]
    a_next = a0 + ia[np.minimum(i_now + 1, len(ia) - 1)]
    b_next = b0 + ib[np.minimum(j_now + 1, len(ib) - 1)]
    third = np.where(is_a, a_next, b_next)
    tris = np.column_stack([a_cur, b_cur, third]).astype(np.int64)
    # drop degenerate triangles (a row of one point closing on itself)
    ok = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])
    return tris[ok]


def _counter_clockwise(xy: NDArray, faces: NDArray) -> NDArray:
    if len(faces) == 0:
        return faces
    a, b, c = xy[faces[:, 0]], xy[faces[:, 1]], xy[faces[:, 2]]
    area2 = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    faces = faces.copy()
    flip = area2 < 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return faces[np.abs(area2) > 1e-14]


def facet_vertex_normals(vertices: NDArray, faces: NDArray) -> NDArray:
    """Area-weighted vertex normals towards +z; vertices shared only within a panel, so gaps
    never mix normals."""
    v = vertices[faces]
    cross = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, faces[:, k], cross)
    normals[normals[:, 2] < 0] *= -1.0
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.where(length > 0, length, 1.0)


# --- meshes from files ----------------------------------------------------------------------
@dataclass(frozen=True)
class ParaboloidFit:
    """Best-fit paraboloid z = z0 + ((x - x0)^2 + (y - y0)^2) / (4F) of a mesh (m)."""

    F: float
    x0: float
    y0: float
    z0: float
    rms: float


def fit_paraboloid(points: NDArray, F: float | None = None) -> ParaboloidFit:
    """Least-squares paraboloid with its axis along z through ``points`` (n, 3), metres.

    With ``F`` given only the vertex (x0, y0, z0) is fitted: to first order that removes the
    piston and tilts of the surface and keeps its focus term.
    """
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    if F is not None:
        k = 1.0 / (4.0 * F)
        A = np.column_stack([np.ones_like(x), x, y])
        coef, *_ = np.linalg.lstsq(A, z - k * (x * x + y * y), rcond=None)
        a, b, c = coef
        model = A @ coef + k * (x * x + y * y)
    else:
        A = np.column_stack([np.ones_like(x), x, y, x * x + y * y])
        coef, *_ = np.linalg.lstsq(A, z, rcond=None)
        a, b, c, k = coef
        model = A @ coef
    if not k > 0:
        raise MeshError("the mesh is not a dish opening towards +z (no paraboloid fits)")
    x0, y0 = -b / (2 * k), -c / (2 * k)
    z0 = a - k * (x0 * x0 + y0 * y0)
    rms = float(np.sqrt(np.mean((model - z) ** 2)))
    return ParaboloidFit(1.0 / (4.0 * k), float(x0), float(y0), float(z0), rms)


def axis_tilt(points: NDArray, samples: int = 20_000) -> tuple[float, float]:
    """(tilt, RMS) of the paraboloid whose axis may lean off z that fits ``points`` (n, 3) m
    best: the axis's angle from +z (rad) and the fit's RMS (m), to set against
    :func:`fit_paraboloid`'s about z. A dish exported with its axis tilted departs from the
    axial fit by a few mm (a 12 m dish at 5 deg: 11.7 mm RMS), under the not-a-dish bound,
    and reads as that much deformation. The points are rotated by two small angles about x
    and y (Nelder-Mead over :func:`fit_paraboloid`'s RMS; up to ``samples`` points, evenly
    taken)."""
    from scipy.optimize import minimize

    pts = np.asarray(points, dtype=np.float64)
    pts = pts[:: max(1, len(pts) // samples)]
    centre = pts.mean(axis=0)

    def rms(angles: NDArray) -> float:
        ax, ay = angles
        cx, sx, cy, sy = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay)
        rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
        ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
        try:
            return fit_paraboloid((pts - centre) @ (ry @ rx).T).rms
        except MeshError:
            return math.inf

    best = minimize(rms, np.zeros(2), method="Nelder-Mead",
                    options={"xatol": 1e-6, "fatol": 1e-12, "initial_simplex":
                             np.array([[0.0, 0.0], [0.05, 0.0], [0.0, 0.05]])})
    ax, ay = best.x
    tilt = float(np.arccos(np.clip(np.cos(ax) * np.cos(ay), -1.0, 1.0)))
    return tilt, float(best.fun)


#: a connected piece of a mesh is not reflector surface (a feed, a strut, a loose plate) when its
#: vertices depart from the dish's paraboloid by more than this fraction of the dish's depth
#: D^2 / (16 F) RMS, and by more than STRAY_OVER_MEDIAN times the other pieces' median, each
#: weighted by its vertices (the panels of a dish that is not a paraboloid all depart alike, and
#: stay; four legs beside a one-piece dish are four pieces against one, but few vertices)
STRAY_PIECE_OF_DEPTH = 0.05
STRAY_OVER_MEDIAN = 10.0


def _fit_dish(vertices: NDArray, faces: NDArray, F: float | None) -> ParaboloidFit:
    """:func:`fit_paraboloid` of a mesh's vertices (m) after refusing (MeshError, one line)
    any connected piece that is not dish surface: each such piece, worst first, is left out
    of the fit it would skew (a feed horn at the focus took a 25 m dish's F from 7.5 to 8.1 m)
    until none is left, then all are named."""
    n = len(vertices)
    piece = _vertex_pieces(faces, n)
    on_faces = np.zeros(n, bool)
    on_faces[faces.ravel()] = True
    pieces = np.unique(piece[on_faces])
    kept = on_faces.copy()
    stray: list[tuple[int, float, float]] = []
    while True:
        fit = fit_paraboloid(vertices[kept], F)
        if len(pieces) - len(stray) < 2:
            break
        dx, dy = vertices[:, 0] - fit.x0, vertices[:, 1] - fit.y0
        departure = vertices[:, 2] - fit.z0 - (dx * dx + dy * dy) / (4.0 * fit.F)
        D = 2.0 * float(np.max(np.hypot(dx[kept], dy[kept])))
        depth = D * D / (16.0 * fit.F)
        left = [i for i in pieces if i not in {s for s, _, _ in stray}]
        size = np.array([np.count_nonzero(on_faces & (piece == i)) for i in left])
        rms = np.array([np.sqrt(np.mean(departure[on_faces & (piece == i)] ** 2)) for i in left])
        worst = int(np.argmax(rms))
        if not (rms[worst] > STRAY_PIECE_OF_DEPTH * depth
                and rms[worst] > STRAY_OVER_MEDIAN * _weighted_median(np.delete(rms, worst),
                                                                      np.delete(size, worst))):
            break
        stray.append((int(left[worst]), float(rms[worst]), depth))
        kept &= piece != left[worst]
    if stray:
        described = "; ".join(
            f"{int(np.count_nonzero(piece == i))} vertices about "
            f"({', '.join(f'{c:.3g}' for c in vertices[piece == i].mean(axis=0))}) m depart "
            f"{rms:.3g} m RMS ({100 * rms / depth:.0f} % of the dish's depth)"
            for i, rms, depth in stray)
        what = "a piece of the mesh is" if len(stray) == 1 else f"{len(stray)} pieces of the mesh are"
        raise MeshError(f"{what} not dish surface: {described}; a reflector mesh holds the dish's "
                        "panels only: remove them, or give feed, legs or cabin as [[obstacle]] "
                        "entries")
    return fit


def _weighted_median(values: NDArray, weights: NDArray) -> float:
    """The value below which half the total weight lies."""
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])


def load_reflector(path: str | Path, unit: float = 1.0, F: float | None = None,
                   ideal_path: str | Path | None = None, unit_setting: str = "dish.mesh_unit_m",
                   ) -> tuple[Reflector, Reflector, ParaboloidFit]:
    """Load any mesh trimesh reads (STL, PLY, OBJ, GLB) as the deformed reflector.

    Returns (ideal, deformed, fit). The mesh is shifted so the best-fit paraboloid's vertex is
    the origin; the ideal counterpart is ``ideal_path`` (same triangulation required) or the
    mesh's own vertices moved onto the paraboloid z = r^2/(4F) (F given, or fitted). Panels
    are the mesh's connected pieces. ``unit`` scales file coordinates to metres;
    ``unit_setting`` is how the caller's user sets it, named when the span looks wrong.
    """
    mesh = _read_mesh(path, unit, unit_setting)
    try:
        fit = _fit_dish(np.asarray(mesh.vertices, dtype=np.float64),
                        np.asarray(mesh.faces, dtype=np.int64), F)
    except MeshError as exc:
        raise MeshError(f"{path}: {exc}") from None
    _check_one_sheet(mesh, path)  # after the fit, which names stray pieces (a horn, legs) better
    F_used = fit.F
    shift = np.array([fit.x0, fit.y0, fit.z0])
    vertices = np.asarray(mesh.vertices, dtype=np.float64) - shift
    faces = np.asarray(mesh.faces, dtype=np.int64)
    faces = _faces_up(vertices, faces)
    panel = _components(faces, len(vertices))
    D = 2.0 * float(np.max(np.hypot(vertices[:, 0], vertices[:, 1])))
    deformed = _on_own_surface(vertices, faces, panel, F_used, D)
    if ideal_path is not None:
        iv = _ideal_vertices(ideal_path, path, unit, np.asarray(mesh.vertices, dtype=np.float64)) - shift
    else:
        iv = vertices.copy()
        iv[:, 2] = (iv[:, 0] * iv[:, 0] + iv[:, 1] * iv[:, 1]) / (4.0 * F_used)
    ideal = _on_own_surface(iv, faces, panel, F_used, D)
    return ideal, deformed, fit


def _on_own_surface(vertices: NDArray, faces: NDArray, face_panel: NDArray, F: float,
                    D: float) -> Reflector:
    """A loaded mesh as a reflector whose smooth surface is the paraboloid of focal length F
    plus the vertices' departure from it (:class:`raysim.surface.departure.MeshDeparture`,
    blended over the mesh's own faces, so each connected piece ``face_panel`` alone); normals
    from that surface."""
    from raysim.surface.departure import MeshDeparture, vertex_faces

    x, y = vertices[:, 0], vertices[:, 1]
    departure = vertices[:, 2] - (x * x + y * y) / (4.0 * F)
    surface = ParaboloidSurface(F, departure=MeshDeparture(vertices[:, :2], departure, faces))
    normals = surface.normal(x, y, vertex_faces(faces, len(vertices)))
    return Reflector(vertices, faces, face_panel, normals, F, D, surface)


def _ideal_vertices(ideal_path: str | Path, path: str | Path, unit: float,
                    merged: NDArray) -> NDArray[np.float64]:
    """The ideal mesh's vertices (m) in the order of the deformed mesh's ``merged`` ones.

    Both files must hold the same triangulation, vertex for vertex as written. Coincident
    vertices are merged by the deformed mesh's coincidences, not the ideal's: panels that
    touch on the design surface and part when deformed are one piece in the ideal file alone,
    and merging each file by its own would give the two different triangulations.
    """
    import trimesh
    from scipy.spatial import cKDTree

    ideal = _read_mesh(ideal_path, unit)  # the file's own checks (units, finite, triangles)
    raw = [trimesh.load(Path(p), force="mesh", process=False) for p in (path, ideal_path)]
    same = raw[0].vertices.shape == raw[1].vertices.shape and np.array_equal(raw[0].faces, raw[1].faces)
    if not same:
        raise MeshError(f"{ideal_path}: the ideal mesh must share the deformed mesh's triangulation")
    raw_deformed = np.asarray(raw[0].vertices, dtype=np.float64) * unit
    raw_ideal = np.asarray(raw[1].vertices, dtype=np.float64) * unit
    tol = 2.0 * MERGE_SHARE * max(float(np.ptp(merged)), 1.0)  # as _read_mesh merges them
    distance, index = cKDTree(merged).query(raw_deformed)
    used = distance <= tol  # vertices of dropped faces were removed from ``merged``
    out = np.full_like(merged, np.nan)
    out[index[used]] = raw_ideal[used]
    spread = np.abs(out[index[used]] - raw_ideal[used]).max(initial=0.0)
    if not np.all(np.isfinite(out)) or spread > 1e-6 * float(np.ptp(ideal.vertices)):
        raise MeshError(f"{ideal_path}: the ideal mesh must share the deformed mesh's triangulation "
                        "(vertices that coincide in the deformed mesh do not in the ideal)")
    return out


MAX_MESH_SPAN_M = 1000.0  # the largest dish this project is for is 110 m
MERGE_SHARE = 1e-7  # vertices closer than this share of the mesh's span are one vertex
MIN_MESH_SPAN_M = 0.1


def setting_line(unit_setting: str, unit: float) -> str:
    """How to set the mesh's unit to ``unit`` (m per file unit): a scene's key or a CLI option."""
    if unit_setting.startswith("--"):
        return f"give {unit_setting} {unit:g}"
    return f"set {unit_setting} = {unit:g}"


def _read_mesh(path: str | Path, unit: float, unit_setting: str = "dish.mesh_unit_m"):
    import trimesh

    path = Path(path)
    if path.is_dir():
        raise MeshError(f"{path}: is a folder, give a mesh file")
    if not path.is_file():
        raise MeshError(f"{path}: no such mesh file")
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many kinds for unreadable files
        raise MeshError(f"{path}: trimesh cannot read it ({exc.__class__.__name__}: {exc})") from exc
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError(f"{path}: {_cut_short(path) or 'holds no triangles'}")
    if not np.all(np.isfinite(np.asarray(mesh.vertices))):  # processing would drop them silently
        raise MeshError(f"{path}: holds vertices that are not finite numbers (NaN or infinite)")
    mesh.process()  # what loading with process=True does: merge duplicate vertices
    # and merge again ignoring texture coordinates and normals (a textured OBJ keeps every
    # face's corners apart by their UVs); if the faces are still mostly pieces of their own,
    # the file wrote each face's corners anew with rounding differences: merge within
    # MERGE_SHARE of the span. Otherwise each triangle would be a panel of its own, and
    # go+edge would diffract from every triangle's edges
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if np.unique(_vertex_pieces(faces, len(mesh.vertices))[faces[:, 0]]).size > 0.5 * len(faces):
        _merge_close_vertices(mesh, MERGE_SHARE * float(np.max(np.ptp(np.asarray(mesh.vertices), axis=0))))
    _drop_repeated_faces(mesh)
    if len(mesh.faces) == 0:
        raise MeshError(f"{path}: holds no triangles (every face repeats a vertex)")
    mesh.apply_scale(unit)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    if not np.all(np.isfinite(vertices)):
        raise MeshError(f"{path}: holds vertices that are not finite numbers")
    _drop_flat_faces(mesh, path)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    span = float(np.max(np.ptp(vertices[:, :2], axis=0)))
    if span > MAX_MESH_SPAN_M:
        raise MeshError(f"{path}: spans {span:g} m across with {unit_setting} = {unit:g}: not a "
                        f"dish in metres (is the file in mm? then {setting_line(unit_setting, 0.001)})")
    if span < MIN_MESH_SPAN_M:
        raise MeshError(f"{path}: spans only {span:g} m across with {unit_setting} = {unit:g}: "
                        f"is {unit_setting} right?")
    return mesh


def _drop_repeated_faces(mesh) -> None:
    """Drop faces that name one vertex twice (no triangle) and every repeat of a face (CAD
    exports often hold both): a repeated face would radiate its currents twice and double the
    intensity it lights. The test is on vertex indices alone, so an ideal mesh of the same
    triangulation loses the same faces."""
    faces = np.sort(np.asarray(mesh.faces, dtype=np.int64), axis=1)
    keep = np.zeros(len(faces), dtype=bool)
    keep[np.unique(faces, axis=0, return_index=True)[1]] = True
    keep &= (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
    if not keep.all():
        mesh.update_faces(keep)
        mesh.remove_unreferenced_vertices()


def _cut_short(path: Path) -> str | None:
    """Why an STL file that gave no triangles gave none, where its header tells: a binary
    STL is an 80-byte header, a 4-byte triangle count n and 50 bytes a triangle, so a file
    shorter than 84 + 50 n was cut short (a copy or download that stopped)."""
    if path.suffix.lower() != ".stl" or (size := path.stat().st_size) < 134:
        return None
    with open(path, "rb") as f:
        f.seek(80)
        n = int.from_bytes(f.read(4), "little")
        first = np.frombuffer(f.read(48), dtype="<f4")  # the first triangle's normal, corners
    # random bytes read as floats are mostly huge, tiny or NaN; a mesh's are not
    plausible = np.all(np.isfinite(first)) and np.all(np.abs(first) < 1e9)
    if plausible and 84 + 50 * n > size:
        return (f"a binary STL cut short: its header counts {n} triangles ({84 + 50 * n} bytes), "
                f"the file holds {size} bytes ({(size - 84) // 50} whole triangles)")
    return None


def _merge_close_vertices(mesh, distance: float) -> None:
    """Make vertices within ``distance`` of each other (chains of them) one vertex, at the
    first one's place: rounding to a grid would leave apart a pair that straddles a grid line."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    v = np.asarray(mesh.vertices, dtype=np.float64)
    pairs = cKDTree(v).query_pairs(distance, output_type="ndarray") if distance > 0 else None
    if pairs is None or len(pairs) == 0:
        return
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(v), len(v)))
    _, label = connected_components(graph, directed=False)
    first = np.full(label.max() + 1, len(v))
    np.minimum.at(first, label, np.arange(len(v)))
    mesh.faces = first[label][np.asarray(mesh.faces)]
    mesh.remove_unreferenced_vertices()


def _drop_flat_faces(mesh, path: str | Path) -> None:
    """Drop faces of no area: three points on a line to the file's precision (twice the area
    below 1e-5 of the longest edge squared, a sliver 1 m long and 10 um high; a midpoint
    stored in float32 reaches 1e-6). They have no normal: their NaN normals and edges made a
    deformed map wholly NaN, and a point in the middle of an edge counted as departure."""
    v = np.asarray(mesh.vertices, dtype=np.float64)[np.asarray(mesh.faces)]
    area2 = np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    longest = np.max(np.linalg.norm(v - np.roll(v, 1, axis=1), axis=2), axis=1)
    keep = area2 > 1e-5 * longest**2
    if not keep.all():
        mesh.update_faces(keep)
        mesh.remove_unreferenced_vertices()
        if len(mesh.faces) == 0:
            raise MeshError(f"{path}: holds no triangles of any area")


#: a reflecting sheet covers its footprint once: the faces' areas seen along z add up to at most
#: the convex hull of the vertices seen so (less the gaps); a mesh above this share of it holds
#: two layers (a panel's front and back faces, exported as a solid)
MAX_COVER = 1.02
#: faces steeper than this (|n_z| below it: 78 deg from the axis) are side walls, not a dish
#: (a dish of F/D 0.1 meets its rim at n_z = 0.37)
MIN_NZ = 0.2


def _check_one_sheet(mesh, path: str | Path) -> None:
    """Refuse a mesh that is not one reflecting sheet: two layers over each other (a solid's
    front and back) or side walls. The ideal is the mesh moved onto the paraboloid, so a
    back layer would land on the front one and reflect the aperture twice."""
    from scipy.spatial import ConvexHull, QhullError

    v = np.asarray(mesh.vertices, dtype=np.float64)
    tri = v[np.asarray(mesh.faces)]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(n, axis=1)
    nz = np.abs(n[:, 2]) / np.maximum(2.0 * area, 1e-300)
    steep = float(area[nz < MIN_NZ].sum() / area.sum())
    if steep > 1e-3:
        raise MeshError(f"{path}: {100 * steep:.1f} % of its area is side walls (faces within "
                        f"{np.degrees(np.arccos(MIN_NZ)):.0f} deg of the dish's axis): give the "
                        "reflecting surface alone (a panel exported as a solid has walls and a back)")
    try:
        hull = ConvexHull(v[:, :2]).volume  # in 2-D, the hull's area
    except QhullError:
        return  # no footprint (a line): the dish checks refuse it
    cover = float((0.5 * np.abs(n[:, 2])).sum() / hull)
    if cover > MAX_COVER:
        raise MeshError(f"{path}: covers its footprint {cover:.2f} times: it holds more than one "
                        "layer (a panel's front and back faces, exported as a solid?); give the "
                        "reflecting surface alone")
    twice, covered = _covered_twice(tri[:, :, :2], hull)
    if twice > MAX_OVERLAP * covered:
        raise MeshError(f"{path}: {twice:.3g} m^2 of its footprint ({100 * twice / covered:.2g} %) "
                        "lie under two faces or more: overlapping faces (a panel exported twice, "
                        "or panels overlapping at a seam?) would each reflect the wave there; give "
                        "one reflecting sheet")


#: share of a mesh's footprint that may lie under two faces: a sheet's faces only meet at their
#: edges, which the samples of :func:`_covered_twice` do not count
MAX_OVERLAP = 1e-3
#: samples of the footprint :func:`_covered_twice` takes, about
OVERLAP_SAMPLES = 250_000


def _covered_twice(xy: NDArray, hull: float) -> tuple[float, float]:
    """(area under two faces or more, area under one or more) (m^2, in the file's units) of
    the triangles ``xy`` (F, 3, 2) seen along z, sampled on a square lattice of about
    :data:`OVERLAP_SAMPLES` points over their hull (area ``hull``). A partial second layer (a
    patch exported twice, panels overlapping at a seam) passed the whole-footprint cover test
    and reflected the aperture there twice: 1.8 % more power than the aperture holds, with the
    power balance at round-off. A point counts inside a face strictly (its barycentric weights
    above 1e-9), so a sheet's shared edges are counted once."""
    h = math.sqrt(hull / OVERLAP_SAMPLES)
    lo = xy.reshape(-1, 2).min(axis=0)
    # each face's lattice points: the bounding box's, made a face at a time by one repeat
    i0 = np.ceil((xy[:, :, 0].min(axis=1) - lo[0]) / h - 0.5).astype(np.int64)
    i1 = np.floor((xy[:, :, 0].max(axis=1) - lo[0]) / h - 0.5).astype(np.int64)
    j0 = np.ceil((xy[:, :, 1].min(axis=1) - lo[1]) / h - 0.5).astype(np.int64)
    j1 = np.floor((xy[:, :, 1].max(axis=1) - lo[1]) / h - 0.5).astype(np.int64)
    nx, ny = np.maximum(i1 - i0 + 1, 0), np.maximum(j1 - j0 + 1, 0)
    counts = nx * ny
    face = np.repeat(np.arange(len(xy)), counts)
    k = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    i = i0[face] + k // np.maximum(ny[face], 1)
    j = j0[face] + k % np.maximum(ny[face], 1)
    px, py = lo[0] + (i + 0.5) * h, lo[1] + (j + 0.5) * h
    a, b, c = xy[face, 0], xy[face, 1], xy[face, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        u = ((px - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (py - a[:, 1])) / det
        v = ((b[:, 0] - a[:, 0]) * (py - a[:, 1]) - (px - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
    inside = (u > 1e-9) & (v > 1e-9) & (1.0 - u - v > 1e-9)
    cells, hits = np.unique(i[inside] * (int(j1.max(initial=0)) + 2) + j[inside], return_counts=True)
    del cells
    return float((hits >= 2).sum() * h * h), float(len(hits) * h * h)


def _faces_up(vertices: NDArray, faces: NDArray) -> NDArray:
    """Wind every face so its normal points to +z (towards the focus)."""
    v = vertices[faces]
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    nz = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    faces = faces.copy()
    faces[nz < 0] = faces[nz < 0][:, [0, 2, 1]]
    return faces


def _vertex_pieces(faces: NDArray, n_vertices: int) -> NDArray[np.int64]:
    """The connected piece of the mesh each vertex belongs to (a label per vertex)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rows = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]])
    cols = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_vertices, n_vertices))
    return connected_components(graph, directed=False)[1]


def _components(faces: NDArray, n_vertices: int) -> NDArray[np.int64]:
    """Panel id per face: the connected pieces of the mesh, numbered by first appearance."""
    label = _vertex_pieces(faces, n_vertices)
    _, first, inverse = np.unique(label[faces[:, 0]], return_index=True, return_inverse=True)
    rank = np.argsort(np.argsort(first))
    return rank[inverse].astype(np.int64)


def _check_sphere(sphere, ideal: Reflector, path) -> None:
    """The checks a scene's sphere gets against a parametric dish, for a mesh's fitted F and
    D (known only once it is read): the sphere inside the focal length, its first row before
    the rim image theta_rim = 2 atan(D / 4F) (DESIGN: the ideal mapping r = 2F tan(theta/2))."""
    if sphere.radius >= ideal.F:
        raise MeshError(f"{path}: the fitted focal length {ideal.F:.4g} m is not above "
                        f"'sphere.radius_m' = {sphere.radius:g} m (the sphere would cut the dish)")
    rim = 2.0 * np.arctan(ideal.D / (4.0 * ideal.F))  # maps.sphere.theta_rim lies downstream
    if sphere.theta_min >= rim:
        raise MeshError(f"{path}: 'sphere.theta_min_deg' = {np.degrees(sphere.theta_min):g} is beyond "
                        f"the fitted dish's rim image at {np.degrees(rim):.2f} deg: the sphere would "
                        "see no reflection")


#: a scene's ``focal_length_m`` may override a mesh's fitted F on purpose (docs/howto/own-mesh.md),
#: but not so far that the mesh departs from the paraboloid it then names by more than this
#: fraction of the dish's depth D^2 / (16 F) RMS: the bound ``raysim check`` puts on a mesh
MAX_DEPARTURE_OF_DEPTH = 0.02
#: a scene's ``diameter_m`` must match the mesh's D (twice its outermost vertex's radius from
#: the fitted axis) to this fraction: D is measured from the mesh, never set
DIAMETER_TOLERANCE = 0.01


def check_stated_dish(path: str | Path, loaded: Reflector, fit: ParaboloidFit,
                      stated_D: float | None, stated_F: float | None) -> None:
    """Refuse (:class:`~raysim.errors.SceneError`, one line naming both values) a scene's
    ``diameter_m`` (m) that differs from the mesh's D by more than :data:`DIAMETER_TOLERANCE`,
    or a ``focal_length_m`` (m) from which the mesh ``loaded`` (vertex-fitted to it, ``fit``)
    departs by more than :data:`MAX_DEPARTURE_OF_DEPTH` of the dish's depth RMS."""
    D = float(loaded.D)
    if stated_D is not None and abs(stated_D - D) > DIAMETER_TOLERANCE * D:
        raise SceneError(f"{path}: 'dish.diameter_m' = {stated_D:g} m contradicts the mesh, which "
                         f"is D = {D:.4g} m across (twice its outermost vertex's radius; they must "
                         f"agree to {100 * DIAMETER_TOLERANCE:g} %)")
    if stated_F is not None:
        depth = D * D / (16.0 * stated_F)
        if fit.rms > MAX_DEPARTURE_OF_DEPTH * depth:
            try:
                own = f"{fit_paraboloid(loaded.vertices).F:.4g} m"
            except MeshError:
                own = "none (no paraboloid fits)"
            raise SceneError(f"{path}: 'dish.focal_length_m' = {stated_F:g} m contradicts the mesh, "
                             f"whose best-fit paraboloid has F = {own}: the mesh departs "
                             f"{fit.rms:.3g} m RMS from the paraboloid of F = {stated_F:g} m "
                             f"({100 * fit.rms / depth:.0f} % of the dish's depth, at most "
                             f"{100 * MAX_DEPARTURE_OF_DEPTH:g} %)")


def mesh_departure_rms(ideal: Reflector, deformed: Reflector) -> float:
    """RMS (m) over the deformed mesh's vertices of their z less the ideal surface's height
    there (the FieldMap's ``mesh_departure_rms_m``, and the check that a mesh read again is
    the one simulated). At the same (x, y), not vertex by vertex: an FEM mesh whose nodes slid
    along the surface has not departed. (Without an ideal file the two are the same numbers.)"""
    v = deformed.vertices
    if ideal.surface is None:
        below = ideal.vertices[:, 2]
    else:
        below = ideal.surface.height(v[:, 0], v[:, 1], ideal.vertex_surface_panel)
    return float(np.sqrt(np.mean((v[:, 2] - below) ** 2)))


def reflectors_for(scene) -> tuple[Reflector, Reflector]:
    """The (ideal, deformed) reflector pair a :class:`~raysim.scene.scene.Scene` describes, both
    with the scene's obstacles (built on the reflector's focal length). A mesh's D and F are
    checked against the scene's ``diameter_m`` and ``focal_length_m`` where it states them
    (:func:`check_stated_dish`)."""
    dish = scene.dish
    specs = getattr(scene, "obstacles", ())
    if dish.mesh is not None:
        ideal, loaded, fit = load_reflector(dish.mesh, dish.mesh_unit, dish.focal_length, dish.ideal_mesh)
        check_stated_dish(dish.mesh, loaded, fit, getattr(dish, "diameter", None), dish.focal_length)
        _check_sphere(scene.sphere, ideal, dish.mesh)
        obstacles = obstacle_mesh(specs, ideal.F)
        if obstacles is not None:
            ideal, loaded = ideal.with_obstacles(obstacles), loaded.with_obstacles(obstacles)
        if isinstance(scene.deformation, NoDeformation):
            return ideal, loaded
        return ideal, loaded.with_layout_panels(scene.panels).deformed(scene.deformation)
    ideal = paraboloid(dish.diameter, dish.focal_length, dish.resolution, scene.panels)
    obstacles = obstacle_mesh(specs, ideal.F)
    if obstacles is not None:
        ideal = ideal.with_obstacles(obstacles)
    return ideal, ideal.deformed(scene.deformation)
