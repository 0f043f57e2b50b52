"""Geometric optics: a plane wave, ray tubes off the reflector, intensity on the probe sphere.

Frame and units of docs/physics.md (metres, radians; focus at (0, 0, F)). The incident wave is
sampled by rays on a lattice of each mesh face (``subdivisions`` per edge; 1 means the rays
pass through the vertices). For every ray:

1. Warp's BVH (float32) finds the first face the ray meets: a ray whose face lies in front
   of its own point is shadowed.
2. The hit is recomputed in float64 on the smooth surface the scene defines (Newton along
   the ray from the facet point, normal from the surface slopes), or kept on the facet with
   interpolated vertex normals for a mesh loaded from a file.
3. The ray is reflected and followed to where it enters the sphere of radius R.

Neighbouring rays form tubes (the lattice's triangles). A tube carries the power that crosses
its cross-section normal to the incident wave; where it lands on the sphere that power is
spread over the (theta, phi) cells by the exact area each cell shares with the tube (in the
sphere's equal-area Lambert chart). So folds add, gaps and shadows give nothing, and the power
on the sphere equals the lit aperture's power to round-off. Cells hold means: power through
the cell over its area, relative to the incident intensity.

Obstacles in the beam (``Reflector.obstacles``, :mod:`raysim.optics.blockage`): a ray is
blocked when an obstacle crosses its incident leg (from up-beam to its hit) or its reflected
leg (from the hit to where it enters the sphere). A tube whose rays are all blocked carries no
power, one a shadow's edge crosses the share of its sub-rays that pass
(:data:`SHADOW_EDGE_ORDER`). What the obstacles take from the tubes gives each cell its
blocked share (:attr:`GOResult.blocked_share`).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from raysim.errors import RaysimError
from raysim.maps.probe import Probe
from raysim.maps.sphere import SphereGrid
from raysim.optics import runtime
from raysim.optics.blockage import blocked_share, sphere_points
from raysim.optics.bvh import ReflectorBVH
from raysim.progress import Progress
from raysim.surface.deformation import Deformation, NoDeformation
from raysim.surface.mesh import Reflector, paraboloid
from raysim.surface.obstacles import ObstacleMesh

ON_AXIS = (0.0, 0.0, -1.0)


@dataclass(frozen=True)
class GOResult:
    """Outcome of one trace. Powers are in m^2 (units of the incident intensity times area)."""

    intensity: NDArray[np.float64]  # (n_theta, n_phi), cell means relative to incident
    power_lit: float  # power intercepted by the lit tubes (their cross-section area)
    power_on_grid: float  # power that reached the grid's cells
    n_rays: int
    n_tubes: int
    n_shadowed: int  # rays with another face in front of them
    n_missed: int  # lit rays that did not reach the sphere
    seconds: float
    power_read: float | None = None  # with a probe: the lit tubes' power as the probe reads it
    n_blocked: int = 0  # lit rays an obstacle blocks on their incident or reflected leg
    blocked_share: NDArray[np.float64] | None = None  # (n_theta, n_phi); None without obstacles

    @property
    def power_balance(self) -> float:
        """power_on_grid / power_lit - 1 (with a probe: over power_read): zero to round-off
        when the grid sees every tube."""
        lit = self.power_lit if self.power_read is None else self.power_read
        return self.power_on_grid / lit - 1.0 if lit > 0 else float("nan")


# --- ray lattice -----------------------------------------------------------------------------
@lru_cache(maxsize=8)
def _lattice_tables(m: int) -> tuple[NDArray, NDArray]:
    """Barycentric weights (L, 3) of the points of an m-fold face lattice, and its m^2
    sub-triangles (local indices, counter-clockwise like the face)."""
    ij = [(i, j) for j in range(m + 1) for i in range(m + 1 - j)]
    index = {p: k for k, p in enumerate(ij)}
    w = np.array([[1.0 - (i + j) / m, i / m, j / m] for i, j in ij])
    tris = []
    for i, j in ij:
        if i + j < m:
            tris.append((index[i, j], index[i + 1, j], index[i, j + 1]))
        if i + j < m - 1:
            tris.append((index[i + 1, j], index[i + 1, j + 1], index[i, j + 1]))
    return w, np.array(tris, dtype=np.int64)


@dataclass(frozen=True)
class RayLattice:
    """Ray start points on the facets and the tubes joining them."""

    points: NDArray[np.float64]  # (N, 3) on the flat facets
    panel: NDArray[np.int64]  # (N,) panel of each point
    normals: NDArray[np.float64]  # (N, 3) interpolated vertex normals (used without a surface)
    tubes: NDArray[np.int32]  # (T, 3) indices into points


def ray_lattice(reflector: Reflector, subdivisions: int | None = 1) -> RayLattice:
    """Rays on an m-fold lattice of every face (m = ``subdivisions``); m = 1 uses the vertices."""
    m = 1 if subdivisions is None else int(subdivisions)  # None: a Scene's automatic value, outside simulate
    if m < 1:
        raise RaysimError(f"subdivisions must be >= 1, got {m}")
    if m == 1:
        return RayLattice(reflector.vertices, reflector.vertex_surface_panel, reflector.vertex_normals,
                          reflector.faces.astype(np.int32))
    w, local = _lattice_tables(m)
    corners = reflector.vertices[reflector.faces]  # (F, 3, 3)
    points = np.einsum("lk,fkc->flc", w, corners).reshape(-1, 3)
    vn = reflector.vertex_normals[reflector.faces]
    normals = np.einsum("lk,fkc->flc", w, vn).reshape(-1, 3)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    n_faces, n_local = len(reflector.faces), len(w)
    tubes = (local[None, :, :] + n_local * np.arange(n_faces)[:, None, None]).reshape(-1, 3)
    panel = np.repeat(reflector.face_surface_panel, n_local)
    return RayLattice(points, panel, normals, tubes.astype(np.int32))


def ray_subdivisions(reflector: Reflector, ray_spacing: float, minimum: int = 1) -> int:
    """Lattice order m per face so that rays lie about ``ray_spacing`` (m) apart (at least
    ``minimum``): the mesh's longest face edge over the spacing."""
    if not ray_spacing > 0:
        raise RaysimError(f"ray spacing must be > 0 m, got {ray_spacing:g}")
    v = reflector.vertices[reflector.faces]
    longest = float(np.linalg.norm(v - np.roll(v, 1, axis=1), axis=2).max()) if len(v) else 0.0
    return max(int(minimum), int(np.ceil(longest / ray_spacing)))


def wedge_table(grid: SphereGrid, device: str) -> tuple[int, object]:
    """(j_first, Warp vec4d array) of the edge normals of the wedges a tube can cut
    (:func:`raysim.optics.kernels.go.wedge_sides`), made once per grid.

    A full circle's tubes span phi from -2 pi to 2 pi before wrapping (the first corner's
    atan2 plus a turn of at most pi either way), so its table holds those wedges; another
    grid's tubes are clipped to its own wedges 0 .. n_phi - 1 only.
    """
    wp = runtime.init()
    from raysim.optics.kernels import go as K

    if grid.full_circle:
        j_first = int(np.floor((-2.0 * np.pi - grid.phi_min) / grid.dphi)) - 1
        j_last = int(np.floor((2.0 * np.pi - grid.phi_min) / grid.dphi)) + 1
    else:
        j_first, j_last = 0, grid.n_phi - 1
    sides = wp.zeros(j_last - j_first + 1, dtype=wp.vec4d, device=device)
    runtime.launch(K.wedge_sides, sides.shape[0],
                   [float(grid.phi_min), float(grid.dphi), j_first, sides], device)
    return j_first, sides


def tube_power(lattice: RayLattice, k_hat: NDArray) -> NDArray[np.float64]:
    """Power of each tube: its cross-section normal to the incident wave (m^2, I0 = 1)."""
    p = lattice.points[lattice.tubes]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return 0.5 * np.abs(cross @ k_hat)


def lift_to_surface(reflector: Reflector, lattice: RayLattice, k_hat: NDArray,
                    iterations: int = 8) -> tuple[NDArray, NDArray]:
    """float64 hit points and unit normals of the lattice rays on the reflector.

    With a smooth surface, Newton's method along each ray from its facet point solves
    z(t) = s(x(t), y(t)); on axis one step is exact. Without one, the facet point and the
    interpolated vertex normal stand.
    """
    surface = reflector.surface
    if surface is None:
        return lattice.points, lattice.normals
    p0 = lattice.points
    t = np.zeros(len(p0))
    for _ in range(iterations):
        p = p0 + t[:, None] * k_hat
        g = p[:, 2] - surface.height(p[:, 0], p[:, 1], lattice.panel)
        sx, sy = surface.slope(p[:, 0], p[:, 1], lattice.panel)
        dg = k_hat[2] - sx * k_hat[0] - sy * k_hat[1]
        step = g / dg
        t -= step
        if np.max(np.abs(step)) < 1e-13:
            break
    hits = p0 + t[:, None] * k_hat
    return hits, surface.normal(hits[:, 0], hits[:, 1], lattice.panel)


# --- the trace ------------------------------------------------------------------------------
def trace(reflector: Reflector, grid: SphereGrid, direction=ON_AXIS, subdivisions: int | None = 1,
          device: str | None = "cpu", progress: Progress | None = None,
          probe: Probe | None = None, e_hat=None) -> GOResult:
    """GO intensity of ``reflector`` on ``grid`` for a plane wave travelling along ``direction``.

    Returns cell means relative to the incident intensity (see the module docstring); with a
    ``probe`` (not the ideal meter), cell means of what it reads of the wave polarised along
    ``e_hat`` (unit, transverse to ``direction``; None: x, for the on-axis wave), see
    :mod:`raysim.optics.goprobe`.
    """
    start = time.perf_counter()
    result = Tracer(reflector, grid, direction, subdivisions, device).trace(reflector, progress,
                                                                            probe, e_hat)
    return replace(result, seconds=time.perf_counter() - start)


class Tracer:
    """One GO set-up (mesh topology, sphere grid, wave, lattice) traced for many vertex sets.

    Built from a ``template`` reflector; :meth:`trace` then takes the template or any twin
    that shares its faces and panels and differs only in its vertices (``Reflector.deformed``),
    and gives what :func:`trace` gives for that twin, bit for bit. Kept between traces: the
    float32 BVH, whose bounds are refitted to each twin's vertices instead of being rebuilt
    (the ray queries return the nearest hit whatever the tree's shape, so the lit test does
    not change); the lattice's tubes and the device arrays of the sphere's tables; and, for a
    wave along -z over a twin with the template's (x, y), each tube's power (its
    cross-section normal to the wave depends on (x, y) alone there).

    With ``footprint_shortcut``, a wave along -z and rays at the vertices (``subdivisions``
    1), a twin with the template's (x, y) skips the BVH and its visibility test when the
    template's vertices stand clear of the faces they are not corners of
    (:func:`raysim.surface.footprint.vertices_clear_of_other_faces`, checked once, here): a
    ray along -z through a vertex can then meet only that vertex's own faces, at the vertex,
    so the test would find every ray lit.
    """

    def __init__(self, template: Reflector, grid: SphereGrid, direction=ON_AXIS,
                 subdivisions: int | None = 1, device: str | None = "cpu",
                 footprint_shortcut: bool = False) -> None:
        wp = runtime.init()
        self.device = runtime.resolve_device(device)
        if not grid.full_circle and grid.dphi > np.pi:
            raise RaysimError("a phi cell wider than 180 deg is only supported as the full circle")
        self.template, self.grid = template, grid
        self.subdivisions = 1 if subdivisions is None else int(subdivisions)
        k_hat = np.asarray(direction, dtype=np.float64)
        self.k_hat = k_hat / np.linalg.norm(k_hat)
        dev = self.device
        lattice = ray_lattice(template, self.subdivisions)
        self.n_rays, self.n_tubes = len(lattice.points), len(lattice.tubes)
        self.bvh = ReflectorBVH.build(template, dev)
        self._bvh_of: Reflector = template  # the reflector whose vertices the BVH holds
        self._tubes = wp.array(lattice.tubes, dtype=wp.vec3i, device=dev)
        self._rho_edges = wp.array(2.0 * np.sin(0.5 * grid.theta_edges), dtype=wp.float64, device=dev)
        self._j_first, self._sides = wedge_table(grid, dev)
        self._lattice = lattice  # the template's
        self._axial = bool(self.k_hat[0] == 0.0 and self.k_hat[1] == 0.0)
        self._power = tube_power(lattice, self.k_hat) if self._axial else None
        self._lock = threading.Lock()
        self._clear = False  # whether the footprint shortcut holds for this template
        if footprint_shortcut and self._axial and self.subdivisions == 1:
            from raysim.surface.footprint import vertices_clear_of_other_faces

            self._clear = vertices_clear_of_other_faces(template.vertices, template.faces)

    def _check_twin(self, reflector: Reflector) -> None:
        t = self.template
        if reflector is t:
            return
        if reflector.faces is not t.faces and not np.array_equal(reflector.faces, t.faces):
            raise RaysimError("a Tracer traces twins of its template only (the same faces)")
        if reflector.face_panel is not t.face_panel and not np.array_equal(reflector.face_panel,
                                                                           t.face_panel):
            raise RaysimError("a Tracer traces twins of its template only (the same panels)")

    def _twin_lattice(self, reflector: Reflector) -> RayLattice:
        """The rays of ``reflector``: its own points and normals, the template's tubes and panels."""
        t = self._lattice
        if reflector is self.template:
            return t
        if self.subdivisions == 1:
            return RayLattice(reflector.vertices, t.panel, reflector.vertex_normals, t.tubes)
        return ray_lattice(reflector, self.subdivisions)

    def _update_bvh(self, reflector: Reflector) -> None:
        """Refit the BVH's bounds to ``reflector``'s vertices (float32), unless it has them."""
        if reflector is self._bvh_of:
            return
        self.bvh.refit(reflector)
        self._bvh_of = reflector

    def _all_lit(self, same_xy: bool) -> bool:
        """Whether the footprint shortcut decides that every ray of a reflector is lit
        (``same_xy``: whether its vertices' (x, y) are the template's, :meth:`_same_xy`)."""
        return self._clear and same_xy

    def _same_xy(self, reflector: Reflector) -> bool:
        t = self.template.vertices
        return reflector is self.template or np.array_equal(reflector.vertices[:, :2], t[:, :2])

    def _tube_power(self, same_xy: bool, lattice: RayLattice) -> NDArray[np.float64]:
        """Power of each tube: the template's where only z moved under an axial wave."""
        if self._power is None:
            return tube_power(lattice, self.k_hat)
        return self._power if same_xy else tube_power(lattice, self.k_hat)

    def trace(self, reflector: Reflector, progress: Progress | None = None,
              probe: Probe | None = None, e_hat=None) -> GOResult:
        """The GO result of ``reflector`` (the template or a twin of it) as ``probe`` reads
        it (None: the ideal meter); see :func:`trace`.

        One trace at a time: the BVH holds one twin's vertices (concurrent calls queue)."""
        with self._lock:
            return self._trace(reflector, progress, probe, e_hat)

    def _trace(self, reflector: Reflector, progress: Progress | None, probe: Probe | None = None,
               e_hat=None) -> GOResult:
        wp = runtime.init()
        from raysim.optics.kernels import go as K

        self._check_twin(reflector)
        start = time.perf_counter()
        report = progress or (lambda stage, fraction: None)
        dev, grid, k_hat = self.device, self.grid, self.k_hat
        focus = np.array([0.0, 0.0, reflector.F])

        report("lattice", 0.0)
        lattice = self._twin_lattice(reflector)
        n_rays = len(lattice.points)

        report("bvh", 0.1)
        same_xy = self._same_xy(reflector)  # one comparison of the (x, y) for the whole trace
        if self._all_lit(same_xy):
            report("visibility", 0.2)
            lit_np = np.ones(n_rays, dtype=bool)
        else:
            self._update_bvh(reflector)
            report("visibility", 0.2)
            lit_np = self.bvh.lit(lattice.points, k_hat, obstacles=False)

        report("surface", 0.4)
        hits, normals = lift_to_surface(reflector, lattice, k_hat)

        report("reflect", 0.5)
        chart = wp.zeros(n_rays, dtype=wp.vec2d, device=dev)
        ok = wp.array(lit_np.astype(np.int32), dtype=wp.int32, device=dev)
        runtime.launch(K.reflect_to_sphere, n_rays,
                            [wp.array(hits, dtype=wp.vec3d, device=dev),
                             wp.array(normals, dtype=wp.vec3d, device=dev),
                             wp.vec3d(*k_hat), wp.vec3d(*focus), float(grid.radius), ok, chart], dev)
        ok_np = ok.numpy().astype(bool)

        power_t = self._tube_power(same_xy, lattice)
        # every tube is lit when every ray is (the footprint shortcut's usual case): no need
        # to gather the rays' flags per tube
        tube_lit = np.ones(len(lattice.tubes), dtype=bool) if lit_np.all() \
            else lit_np[lattice.tubes].all(axis=1)
        power_read = None
        if probe is not None and not probe.ideal:
            from raysim.optics.goprobe import tube_weights

            e = np.array([1.0, 0.0, 0.0]) if e_hat is None else np.asarray(e_hat, dtype=np.float64)
            power_t = power_t * tube_weights(probe, lattice.tubes, normals, k_hat, e,
                                             chart.numpy(), ok_np)
        blocked_np = removed = None
        if self.bvh.obstacles is not None:
            report("obstacles", 0.55)
            chart_np = chart.numpy()
            blocked_np = self._blocked(hits, lit_np, ok_np, chart_np, focus)
            corners = blocked_np[lattice.tubes]
            reached = ok_np[lattice.tubes].all(axis=1)
            # each tube's clear share: 0 when its three rays are blocked, 1 when none is, and
            # for a tube a shadow's edge crosses the share of its sub-rays that pass (dropping
            # such tubes whole overstated the blocked power by about a tube along every edge:
            # +21 % for a 1 m disk at the focus on 0.1 m triangles)
            share = np.where(corners.any(axis=1), 0.0, 1.0)
            edge = np.flatnonzero(corners.any(axis=1) & ~corners.all(axis=1) & reached & tube_lit)
            share[edge] = self._clear_share(lattice.tubes[edge], hits, chart_np, focus)
            # what the obstacles take from the tubes, for the cells' blocked share
            gone = np.flatnonzero((share < 1.0) & reached)
            removed = self._deposit(chart, ok, wp.array(lattice.tubes[gone], dtype=wp.vec3i, device=dev),
                                    power_t[gone] * (1.0 - share[gone]))
            power_t = power_t * share
        if probe is not None and not probe.ideal:
            power_read = float(power_t[tube_lit].sum())

        report("deposit", 0.6)
        power_np = self._deposit(chart, ok, self._tubes, power_t)
        intensity = power_np / grid.cell_area()
        report("done", 1.0)
        return GOResult(
            intensity=intensity,
            power_lit=float(power_t[tube_lit].sum()),
            power_on_grid=float(power_np.sum()),
            n_rays=n_rays,
            n_tubes=self.n_tubes,
            n_shadowed=int((~lit_np).sum()),
            n_missed=int((lit_np & ~ok_np).sum()),
            seconds=time.perf_counter() - start,
            power_read=power_read,
            n_blocked=0 if blocked_np is None else int(blocked_np.sum()),
            blocked_share=None if removed is None else blocked_share(power_np, removed),
        )

    def _deposit(self, chart, ok, tubes, power_t: NDArray[np.float64]) -> NDArray[np.float64]:
        """Power (n_theta, n_phi) the ``tubes`` (Warp vec3i) of power ``power_t`` (m^2) bring to
        the grid's cells, rays flagged by ``ok``."""
        wp = runtime.init()
        from raysim.optics.kernels import go as K

        grid, dev = self.grid, self.device
        polar = wp.zeros(chart.shape[0], dtype=wp.vec3d, device=dev)
        runtime.launch(K.chart_polar, chart.shape[0], [chart, ok, polar], dev)
        power = wp.zeros((grid.n_theta, grid.n_phi), dtype=wp.float64, device=dev)
        runtime.launch(
            K.deposit_tubes, len(power_t),
            [chart, ok, tubes, wp.array(power_t, dtype=wp.float64, device=dev), polar,
             self._rho_edges, self._sides, self._j_first,
             float(grid.theta_min), float(grid.dtheta), grid.n_theta,
             float(grid.phi_min), float(grid.dphi), grid.n_phi, int(grid.full_circle), power],
            dev, private=(15,), min_chunk=2048)
        return power.numpy()

    def _clear_share(self, tubes: NDArray, hits: NDArray, chart: NDArray, focus: NDArray,
                     order: int | None = None) -> NDArray[np.float64]:
        """(len(tubes),) the share of each tube's cross-section whose rays no obstacle blocks:
        the tube cut into order^2 triangles of equal area, a ray at each one's centroid, its
        hit and sphere entry interpolated from the corners' (m)."""
        weights = _centroid_weights(SHADOW_EDGE_ORDER if order is None else order)  # (order^2, 3)
        # the sphere entries of these tubes' corners only, not of the whole lattice's rays
        entry = sphere_points(chart[tubes.reshape(-1)], focus, self.grid.radius).reshape(len(tubes), 3, 3)
        points = np.einsum("sk,tkc->tsc", weights, hits[tubes]).reshape(-1, 3)
        ends = np.einsum("sk,tkc->tsc", weights, entry).reshape(-1, 3)
        obstacles = self.bvh.obstacles
        blocked = obstacles.incident_blocked(points, self.k_hat, self.bvh.standoff)
        clear = ~blocked
        blocked[clear] = obstacles.blocked(points[clear], ends[clear])
        return 1.0 - blocked.reshape(len(tubes), -1).mean(axis=1)

    def _blocked(self, hits: NDArray, lit: NDArray[np.bool_], reached: NDArray[np.bool_],
                 chart: NDArray, focus: NDArray) -> NDArray[np.bool_]:
        """(n_rays,) bool: lit rays an obstacle blocks on the way in (to ``hits``) or out (from
        ``hits`` to their sphere entry, for the rays that ``reached`` the sphere)."""
        obstacles = self.bvh.obstacles
        blocked = np.zeros(len(hits), dtype=bool)
        blocked[lit] = obstacles.incident_blocked(hits[lit], self.k_hat, self.bvh.standoff)
        out = reached & ~blocked
        entry = sphere_points(chart[out], focus, self.grid.radius)
        blocked[out] = obstacles.blocked(hits[out], entry)
        return blocked


#: sub-rays per edge of a tube a shadow's edge crosses (order^2 of them, at the centroids of
#: equal sub-triangles): the blocked power's error along an edge falls from about a tube's
#: width to about 1/order of it
SHADOW_EDGE_ORDER = 8


@lru_cache(maxsize=4)
def _centroid_weights(m: int) -> NDArray[np.float64]:
    """Barycentric weights (m^2, 3) of the centroids of a triangle's m^2 equal sub-triangles
    (m per edge): the upward ones (i, j), i + j <= m - 1, and the downward, i + j <= m - 2."""
    up = [((i + 1 / 3) / m, (j + 1 / 3) / m) for i in range(m) for j in range(m - i)]
    down = [((i + 2 / 3) / m, (j + 2 / 3) / m) for i in range(m - 1) for j in range(m - 1 - i)]
    uv = np.array(up + down)
    return np.column_stack([1.0 - uv.sum(axis=1), uv[:, 0], uv[:, 1]])


class ParaboloidTracer:
    """GO cell-mean intensity of the paraboloid (D, F in m) plus a deformation, on sphere grids.

    The forward model of the inversion: it needs only what every FieldMap carries. The ideal
    mesh (``resolution`` m faces) and one :class:`Tracer` per (D, F, grid) are made once by
    this object and kept while it lives (the last ``keep``); a deformed mesh displaces the ideal
    one and is traced with the BVH refitted. Whoever needs repeated traces holds one (the
    refinement's GO model does). ``obstacles`` (m, reflector frame) stand in the beam of every
    reflector it traces.
    """

    def __init__(self, device: str | None = "cpu", resolution: float = 0.15,
                 subdivisions: int = 1, keep: int = 2, obstacles: ObstacleMesh | None = None) -> None:
        self.device = runtime.resolve_device(device)
        self.resolution, self.subdivisions, self.keep = float(resolution), int(subdivisions), keep
        self.obstacles = obstacles
        self._tracers: dict[tuple, Tracer] = {}

    def tracer(self, grid: SphereGrid, F: float, D: float) -> Tracer:
        """The :class:`Tracer` of the ideal paraboloid (D, F) on ``grid``, made on first use."""
        key = (grid, float(F), float(D))
        if key not in self._tracers:
            while len(self._tracers) >= self.keep:
                self._tracers.pop(next(iter(self._tracers)))
            ideal = paraboloid(float(D), float(F), self.resolution)
            if self.obstacles is not None:
                ideal = ideal.with_obstacles(self.obstacles)
            self._tracers[key] = Tracer(ideal, grid, ON_AXIS, self.subdivisions, self.device)
        return self._tracers[key]

    def intensity(self, grid: SphereGrid, F: float, D: float,
                  deformation: Deformation | None = None, probe: Probe | None = None,
                  polarization: float = 0.0) -> NDArray[np.float64]:
        """GO cell-mean intensity (n_theta, n_phi) on ``grid``, relative to the incident one,
        as ``probe`` reads it (None: the ideal meter) of the on-axis wave polarised at
        ``polarization`` (rad from x)."""
        tracer = self.tracer(grid, F, D)
        ideal = tracer.template
        reflector = ideal if deformation is None or isinstance(deformation, NoDeformation) \
            else ideal.deformed(deformation)
        e_hat = (np.cos(polarization), np.sin(polarization), 0.0)
        return tracer.trace(reflector, None, probe, e_hat).intensity


def forward_intensity(grid: SphereGrid, F: float, D: float, deformation: Deformation | None = None,
                      device: str | None = "cpu", resolution: float = 0.15,
                      subdivisions: int = 1, obstacles: ObstacleMesh | None = None) -> NDArray[np.float64]:
    """GO cell-mean intensity on ``grid`` of the paraboloid (D, F in m) plus ``deformation``,
    with ``obstacles`` in the beam, in one call (:class:`ParaboloidTracer` builds the ideal
    mesh and its tracer; hold one of those for repeated calls)."""
    return ParaboloidTracer(device, resolution, subdivisions, obstacles=obstacles).intensity(
        grid, F, D, deformation)
