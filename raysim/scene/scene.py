"""Scenes: TOML files -> a validated :class:`Scene` in SI units.

A scene names the dish (diameter and focal length, or a mesh file), its panels and gaps, the
surface errors, the source (frequency, direction of incidence, polarization) and the probe
sphere. Keys carry their unit in their name (``diameter_m``, ``frequency_hz``,
``theta_max_deg``, ``amplitude_um``); degrees and micrometres are converted here, at the edge,
and the rest of raysim sees metres, hertz and radians. Every defect raises
:class:`~raysim.errors.SceneError` with one line naming the file and the key.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from raysim.errors import SceneError
from raysim.maps.sphere import SphereGrid, theta_rim
from raysim.scene.deformations import deformation_of
from raysim.scene.schema import INT, LIST, NUM, STR, TABLE, TABLES, KeyChecker, resolve
from raysim.surface.deformation import Deformation
from raysim.surface.panels import PanelLayout

DEFAULT_RESOLUTION = 0.15  # m: triangle edge that keeps GO ratios within 1 % of the signal


@dataclass(frozen=True)
class Dish:
    """The reflector: D and F in metres, or a mesh file (then D and F may be fitted)."""

    diameter: float | None
    focal_length: float | None
    resolution: float = DEFAULT_RESOLUTION
    mesh: Path | None = None
    ideal_mesh: Path | None = None
    mesh_unit: float = 1.0


@dataclass(frozen=True)
class Source:
    """Plane wave: frequency (Hz); it arrives from polar angle ``incidence_theta`` (rad, from +z)
    and azimuth ``incidence_phi`` (rad), so it travels along -(sin t cos p, sin t sin p, cos t);
    ``polarization`` (rad) turns E about the propagation direction, 0 giving E along x on axis.
    """

    frequency_hz: float
    incidence_theta: float = 0.0
    incidence_phi: float = 0.0
    polarization: float = 0.0

    @property
    def direction(self) -> np.ndarray:
        """Unit propagation vector k_hat of the incident wave (reflector frame)."""
        t, p = self.incidence_theta, self.incidence_phi
        return -np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])

    @property
    def e_hat(self) -> np.ndarray:
        """Unit electric-field vector of the incident wave (perpendicular to k_hat)."""
        t, p = self.incidence_theta, self.incidence_phi
        # on axis (t = 0) the basis is x_hat, y_hat; off axis it is rotated with the wave
        u = np.array([math.cos(t) * math.cos(p), math.cos(t) * math.sin(p), -math.sin(t)])
        v = np.array([-math.sin(p), math.cos(p), 0.0])
        e_x = math.cos(p) * u - math.sin(p) * v
        e_y = math.sin(p) * u + math.cos(p) * v
        return math.cos(self.polarization) * e_x + math.sin(self.polarization) * e_y

    @property
    def wavelength(self) -> float:
        return 299_792_458.0 / self.frequency_hz


@dataclass(frozen=True)
class Scene:
    """A validated scene; all values SI (m, Hz, rad). ``text`` is the TOML it came from."""

    name: str
    dish: Dish
    panels: PanelLayout | None
    deformation: Deformation
    source: Source
    sphere: SphereGrid
    subdivisions: int = 1
    text: str = ""
    path: Path | None = None
    method: str = "go"

    @property
    def F(self) -> float:
        if self.dish.focal_length is None:
            raise SceneError("the dish's focal length is not known yet (fit the mesh first)")
        return self.dish.focal_length

    @property
    def D(self) -> float:
        if self.dish.diameter is None:
            raise SceneError("the dish's diameter is not known yet (fit the mesh first)")
        return self.dish.diameter

    def with_overrides(self, frequency_hz: float | None = None, n_theta: int | None = None,
                       n_phi: int | None = None) -> Scene:
        """The same scene with a new frequency (Hz) or sphere grid size, checked again."""
        scene = self
        if frequency_hz is not None:
            _check_frequency(frequency_hz, "--frequency")
            scene = replace(scene, source=replace(scene.source, frequency_hz=float(frequency_hz)))
        if n_theta is not None or n_phi is not None:
            for name, value in (("--n-theta", n_theta), ("--n-phi", n_phi)):
                if value is not None and value < 1:
                    raise SceneError(f"{name} must be >= 1, got {value}")
            sphere = replace(scene.sphere, n_theta=n_theta or scene.sphere.n_theta,
                             n_phi=n_phi or scene.sphere.n_phi)
            scene = replace(scene, sphere=sphere)
        return scene


# the simulation a scene is made for (``raysim simulate`` uses it unless --method says otherwise)
SCENE_METHODS = ("go", "po", "po+ptd", "go+edge")

# --- the schema: section -> key -> expected kind ------------------------------------------
_SCHEMA: dict[str, dict[str, str]] = {
    "": {"name": STR, "description": STR, "method": STR, "dish": TABLE, "panels": TABLE,
         "deformation": TABLES, "source": TABLE, "sphere": TABLE, "go": TABLE},
    "dish": {"diameter_m": NUM, "focal_length_m": NUM, "resolution_m": NUM, "mesh": STR,
             "ideal_mesh": STR, "mesh_unit_m": NUM},
    "panels": {"ring_edges_m": LIST, "panels_per_ring": LIST, "gap_m": NUM, "phi0_deg": NUM},
    "source": {"frequency_hz": NUM, "incidence_theta_deg": NUM, "incidence_phi_deg": NUM,
               "polarization_deg": NUM},
    "sphere": {"radius_m": NUM, "n_theta": INT, "n_phi": INT, "theta_min_deg": NUM,
               "theta_max_deg": NUM, "phi_min_deg": NUM, "phi_max_deg": NUM},
    "go": {"subdivisions": INT},
}
def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene TOML file (relative file names resolve beside it)."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: no such scene file")
    text = path.read_text(encoding="utf-8")
    return parse_scene(text, source=str(path), base=path.parent)


def parse_scene(text: str, source: str = "scene", base: Path | None = None) -> Scene:
    """Validate scene TOML ``text``; ``source`` names it in messages, ``base`` resolves files."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{source}: not valid TOML ({exc})") from exc
    base = base or Path.cwd()
    ctx = KeyChecker(source)
    ctx.check_keys(raw, "", _SCHEMA[""])
    dish = _dish(ctx, raw.get("dish", {}), base)
    panels = _panels(ctx, raw.get("panels"), dish)
    source_ = _source(ctx, raw.get("source", {}))
    sphere = _sphere(ctx, raw.get("sphere", {}), dish)
    go = raw.get("go", {})
    ctx.check_keys(go, "go", _SCHEMA["go"])
    subdivisions = ctx.integer(go, "go", "subdivisions", 1, lo=1, hi=16)
    deformation = deformation_of(ctx, raw.get("deformation", []), dish.diameter, dish.focal_length,
                                 panels, base)
    name = raw.get("name") or (Path(source).stem if source != "scene" else "scene")
    method = raw.get("method", "go")
    if method not in SCENE_METHODS:
        raise ctx.fail("", f"'method' must be one of {', '.join(SCENE_METHODS)}, got {method!r}")
    return Scene(name=str(name), dish=dish, panels=panels, deformation=deformation,
                 source=source_, sphere=sphere, subdivisions=subdivisions, text=text,
                 path=Path(source) if source != "scene" else None, method=method)


def _dish(ctx: KeyChecker, table: dict, base: Path) -> Dish:
    ctx.check_keys(table, "dish", _SCHEMA["dish"])
    mesh = table.get("mesh")
    mesh_path = resolve(ctx, base, mesh, "dish.mesh") if mesh else None
    ideal = table.get("ideal_mesh")
    ideal_path = resolve(ctx, base, ideal, "dish.ideal_mesh") if ideal else None
    if ideal_path and not mesh_path:
        raise ctx.fail("", "'dish.ideal_mesh' needs 'dish.mesh'")
    D = F = None
    if "diameter_m" in table or not mesh_path:
        D = ctx.number(table, "dish", "diameter_m", lo=0.0, lo_open=True)
        if D > 1000.0:
            raise ctx.fail("", f"'dish.diameter_m' = {D:g} m is not a dish: is it in mm?")
    if "focal_length_m" in table or not mesh_path:
        F = ctx.number(table, "dish", "focal_length_m", lo=0.0, lo_open=True)
        if F > 1000.0:
            raise ctx.fail("", f"'dish.focal_length_m' = {F:g} m is not a dish: is it in mm?")
    size = D if D is not None else 100.0
    resolution = ctx.number(table, "dish", "resolution_m", DEFAULT_RESOLUTION, lo=0.0, lo_open=True)
    if resolution > size / 8:
        raise ctx.fail("", f"'dish.resolution_m' = {resolution:g} m is coarser than D/8")
    if D is not None and resolution < D / 20000:
        raise ctx.fail("", f"'dish.resolution_m' = {resolution:g} m would make billions of triangles")
    unit = ctx.number(table, "dish", "mesh_unit_m", 1.0, lo=0.0, lo_open=True)
    return Dish(D, F, resolution, mesh_path, ideal_path, unit)


def _panels(ctx: KeyChecker, table: dict | None, dish: Dish) -> PanelLayout | None:
    if table is None:
        return None
    ctx.check_keys(table, "panels", _SCHEMA["panels"])
    if "ring_edges_m" not in table or "panels_per_ring" not in table:
        raise ctx.fail("", "[panels] needs 'ring_edges_m' and 'panels_per_ring'")
    edges = table["ring_edges_m"]
    counts = table["panels_per_ring"]
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in edges):
        raise ctx.fail("", "'panels.ring_edges_m' must be a list of numbers (m)")
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in counts):
        raise ctx.fail("", "'panels.panels_per_ring' must be a list of integers")
    gap = ctx.number(table, "panels", "gap_m", 0.0, lo=0.0)
    if gap > 0.5:
        raise ctx.fail("", f"'panels.gap_m' = {gap:g} m is wider than any panel gap: is it in mm?")
    if dish.diameter is not None and not math.isclose(edges[-1], dish.diameter / 2, rel_tol=1e-9):
        raise ctx.fail("", f"'panels.ring_edges_m' must end at the rim D/2 = {dish.diameter / 2:g} m, "
                       f"got {edges[-1]:g}")
    phi0 = math.radians(ctx.number(table, "panels", "phi0_deg", 0.0))
    try:
        layout = PanelLayout(tuple(float(e) for e in edges), tuple(counts), gap, phi0)
    except ValueError as exc:
        raise ctx.fail("", f"[panels] {exc}") from exc
    for ring in range(layout.n_rings):
        lo, hi = layout.radial_limits(ring)
        if hi - lo < 4 * gap or hi <= lo:
            raise ctx.fail("", f"'panels.gap_m' = {gap:g} m leaves ring {ring} no panel area")
    return layout


def _check_frequency(f: float, name: str) -> None:
    if not f > 0:
        raise SceneError(f"{name} must be > 0 Hz, got {f:g}")
    if f < 1e6:
        raise SceneError(f"{name} = {f:g} is in Hz: {f:g} Hz is not a microwave; "
                         f"for {f:g} GHz write {f * 1e9:g}")


def _source(ctx: KeyChecker, table: dict) -> Source:
    ctx.check_keys(table, "source", _SCHEMA["source"])
    f = ctx.number(table, "source", "frequency_hz")
    try:
        _check_frequency(f, "'source.frequency_hz'")
    except SceneError as exc:
        raise ctx.fail("", str(exc)) from exc
    t = ctx.number(table, "source", "incidence_theta_deg", 0.0, lo=0.0)
    if t >= 90.0:
        raise ctx.fail("", f"'source.incidence_theta_deg' = {t:g}: the wave must come from above (< 90)")
    p = ctx.number(table, "source", "incidence_phi_deg", 0.0)
    pol = ctx.number(table, "source", "polarization_deg", 0.0)
    return Source(f, math.radians(t), math.radians(p), math.radians(pol))


def _sphere(ctx: KeyChecker, table: dict, dish: Dish) -> SphereGrid:
    ctx.check_keys(table, "sphere", _SCHEMA["sphere"])
    R = ctx.number(table, "sphere", "radius_m", lo=0.0, lo_open=True)
    if dish.focal_length is not None and R >= dish.focal_length:
        raise ctx.fail("", f"'sphere.radius_m' = {R:g} m must be smaller than the focal length "
                       f"{dish.focal_length:g} m (the sphere would cut the dish)")
    n_theta = ctx.integer(table, "sphere", "n_theta", 90, lo=1, hi=20000)
    n_phi = ctx.integer(table, "sphere", "n_phi", 360, lo=1, hi=40000)
    t0 = ctx.number(table, "sphere", "theta_min_deg", 0.0, lo=0.0)
    t1 = ctx.number(table, "sphere", "theta_max_deg", 90.0, hi=90.0)
    if t1 <= t0:
        raise ctx.fail("", f"'sphere.theta_max_deg' = {t1:g} must exceed theta_min_deg = {t0:g}")
    if dish.diameter is not None and dish.focal_length is not None:
        rim = math.degrees(theta_rim(dish.diameter, dish.focal_length))
        if t0 >= rim:
            raise ctx.fail("", f"'sphere.theta_min_deg' = {t0:g} is beyond the rim image at "
                           f"{rim:.2f} deg: the sphere would see no reflection")
    p0 = ctx.number(table, "sphere", "phi_min_deg", 0.0)
    p1 = ctx.number(table, "sphere", "phi_max_deg", p0 + 360.0)
    if not 0 < p1 - p0 <= 360.0:
        raise ctx.fail("", "'sphere.phi_max_deg' - 'phi_min_deg' must lie in (0, 360]")
    return SphereGrid(R, n_theta, n_phi, math.radians(t0), math.radians(t1),
                      math.radians(p0), math.radians(p1))


