"""Scenes: TOML files -> a validated :class:`Scene` in SI units.

A scene names the dish (diameter and focal length, or a mesh file), its panels and gaps, the
surface errors, the obstacles in the beam, the source (frequency, direction of incidence,
polarization), the probe sphere and, optionally, the probe on it (``[probe]``: polarisation
and pattern, :mod:`raysim.maps.probe`; without it an ideal |E|^2 meter). Keys carry their unit
in their name (``diameter_m``, ``frequency_hz``, ``theta_max_deg``, ``amplitude_um``); degrees
and micrometres are converted here, at the edge, and the rest of raysim sees metres, hertz and
radians. Every defect raises
:class:`~raysim.errors.SceneError` with one line naming the file and the key.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from raysim.constants import MAX_FREQUENCY_HZ, MIN_FREQUENCY_HZ, wavelength
from raysim.errors import SceneError
from raysim.files import find_input
from raysim.maps.probe import IDEAL, PROBE_KEYS, Probe, probe_from_table
from raysim.maps.sphere import SphereGrid, theta_rim
from raysim.methods import METHODS
from raysim.scene.deformations import deformation_of
from raysim.scene.obstacles import obstacles_of
from raysim.surface.deformation import Deformation
from raysim.surface.obstacles import Obstacle
from raysim.surface.panels import PanelLayout
from raysim.tomlschema import Table, parse_toml, read_text

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
        return wavelength(self.frequency_hz)


@dataclass(frozen=True)
class Scene:
    """A validated scene; all values SI (m, Hz, rad). ``text`` is the TOML it came from,
    ``path`` its file and ``files`` the files it names."""

    name: str
    dish: Dish
    panels: PanelLayout | None
    deformation: Deformation
    source: Source
    sphere: SphereGrid
    #: GO rays per face edge; None: automatic (1 on a generated dish, whose triangles are
    #: ``dish.resolution``; on a mesh file enough for rays about DEFAULT_RESOLUTION apart:
    #: :func:`raysim.optics.go.mesh_subdivisions`)
    subdivisions: int | None = None
    #: the automatic lattice's ray spacing (m) on a mesh file (None: DEFAULT_RESOLUTION);
    #: set by ``raysim check --resolution``, not by a scene file
    ray_spacing: float | None = None
    text: str = ""
    path: Path | None = None
    method: str = "go"
    files: tuple[Path, ...] = ()  # the files the scene names (meshes, maps, panel tables)
    probe: Probe = IDEAL  # what the power meter on the sphere reads (raysim.maps.probe)
    obstacles: tuple[Obstacle, ...] = ()  # cabins, legs, meshes in the beam (raysim.scene.obstacles)

    def inputs(self) -> list[tuple[str, Path]]:
        """(what, path) of every file this scene was read from, for output checks."""
        out = [("scene file", self.path)] if self.path is not None else []
        return out + [("file the scene names", f) for f in self.files]

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
            check_frequency(frequency_hz, "--frequency")
            scene = replace(scene, source=replace(scene.source, frequency_hz=float(frequency_hz)))
        if n_theta is not None or n_phi is not None:
            n_theta = scene.sphere.n_theta if n_theta is None else n_theta
            n_phi = scene.sphere.n_phi if n_phi is None else n_phi
            check_sphere_cells(n_theta, n_phi, ("--n-theta", "--n-phi"))
            # numpy integers pass the check; the grid keeps plain ints
            scene = replace(scene, sphere=replace(scene.sphere, n_theta=int(n_theta), n_phi=int(n_phi)))
        return scene


# what ``raysim simulate`` runs unless --method says otherwise (defined in raysim.methods)
SCENE_METHODS = METHODS

# the keys of a scene file: the top level and each table
SCENE_KEYS = ("name", "description", "method", "dish", "panels", "deformation", "source",
              "sphere", "go", "probe", "obstacle")
TABLE_KEYS = {
    "dish": ("diameter_m", "focal_length_m", "resolution_m", "mesh", "ideal_mesh", "mesh_unit_m"),
    "panels": ("ring_edges_m", "panels_per_ring", "gap_m", "phi0_deg"),
    "source": ("frequency_hz", "incidence_theta_deg", "incidence_phi_deg", "polarization_deg"),
    "sphere": ("radius_m", "n_theta", "n_phi", "theta_min_deg", "theta_max_deg", "phi_min_deg",
               "phi_max_deg"),
    "go": ("subdivisions",),
    "probe": PROBE_KEYS,
}

# the probe sphere's grid: one set of bounds for the scene file and the --n-theta/--n-phi options
MAX_N_THETA = 9000
MAX_N_PHI = 36000
MAX_CELLS = 10_000_000
# the generated mesh: triangles of about resolution^2 / 2 over the aperture
MAX_FACES = 10_000_000


def check_sphere_cells(n_theta: int, n_phi: int, names: tuple[str, str] = ("n_theta", "n_phi"),
                       source: str = "") -> None:
    """Refuse a probe-sphere grid outside 1..MAX_N_THETA x 1..MAX_N_PHI or over MAX_CELLS cells
    (the one check of the scene file's ``[sphere]`` and the ``--n-theta``/``--n-phi`` options).
    Any integer type counts (Python's or numpy's); bools and floats, even whole ones, do not."""
    prefix = f"{source}: " if source else ""
    for name, value, hi in ((names[0], n_theta, MAX_N_THETA), (names[1], n_phi, MAX_N_PHI)):
        if (isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Integral)
                or not 1 <= value <= hi):
            raise SceneError(f"{prefix}{name} must be an integer in 1..{hi}, got {value!r}")
    cells = int(n_theta) * int(n_phi)  # Python ints: a small numpy type would wrap round
    if cells > MAX_CELLS:
        raise SceneError(f"{prefix}{names[0]} x {names[1]} = {cells:,} cells is over "
                         f"the limit of {MAX_CELLS:,}")


def scene_of(field: Any) -> Scene | None:
    """The scene a FieldMap records (its ``scene`` attribute; ``field`` is the dataset or its
    attributes), or None.

    None when there is no scene (a measured scan) and when the recorded text no longer parses
    here (a mesh or map file it names is absent): every reader works from the FieldMap's
    attributes alone, and a recorded scene only adds to them (the truth, the panel layout).
    """
    attrs = getattr(field, "attrs", field)
    text = attrs.get("scene") if isinstance(attrs, Mapping) else None
    if not text:
        return None
    # the files it names resolve beside the scene file it came from, wherever this runs
    folder = Path(str(attrs.get("scene_folder", "")))
    try:
        return parse_scene(str(text), source="the FieldMap's scene",
                           base=folder if folder.is_absolute() and folder.is_dir() else None)
    except SceneError:
        return None


def recorded_files(field: Any) -> list[tuple[str, Path]]:
    """(what, path) of the files the scene a FieldMap records names (its mesh, maps, panel
    tables; :func:`scene_of`), for output checks: readers of the FieldMap read them (the
    inversion for the truth), and an output there would replace them. None for a measured
    scan or a scene whose files are gone here."""
    scene = scene_of(field)
    return [] if scene is None else [("file the FieldMap's scene names", f) for f in scene.files]


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene TOML file (relative file names resolve beside it). A name
    that is not an existing path may name a shipped example (``paper_go``)."""
    path = find_input(path)
    text = read_text(path, "scene", SceneError)
    return parse_scene(text, source=str(path), base=path.parent)


def parse_scene(text: str, source: str = "scene", base: Path | None = None) -> Scene:
    """Validate scene TOML ``text``; ``source`` names it in messages, ``base`` resolves files."""
    top = Table(parse_toml(text, source, SceneError), source=source, error=SceneError,
                keys=SCENE_KEYS)
    base = base or Path.cwd()
    name = top.string("name", None) or (Path(source).stem if source != "scene" else "scene")
    top.string("description", "")
    method = top.string("method", "go", choices=SCENE_METHODS)
    dish = _dish(top.sub("dish", keys=TABLE_KEYS["dish"]), base)
    panels = _panels(top.sub("panels", keys=TABLE_KEYS["panels"]) if top.has("panels") else None,
                     dish)
    source_ = _source(top.sub("source", keys=TABLE_KEYS["source"]))
    sphere = _sphere(top.sub("sphere", keys=TABLE_KEYS["sphere"]), dish)
    go = top.sub("go", keys=TABLE_KEYS["go"])
    subdivisions = go.integer("subdivisions", None, lo=1, hi=16) if go.has("subdivisions") else None
    go.done()
    probe = probe_from_table(top.sub("probe", keys=TABLE_KEYS["probe"]))
    deformation = deformation_of(top.tables("deformation"), dish.diameter, dish.focal_length,
                                 panels, base)
    obstacles = obstacles_of(top.tables("obstacle"), dish.diameter, dish.focal_length, base)
    top.done()
    return Scene(name=str(name), dish=dish, panels=panels, deformation=deformation,
                 source=source_, sphere=sphere, subdivisions=subdivisions, text=text,
                 path=Path(source) if source != "scene" else None, method=method,
                 files=tuple(top.files), probe=probe, obstacles=obstacles)


def _dish(t: Table, base: Path) -> Dish:
    mesh_path = t.file("mesh", base, None)
    ideal_path = t.file("ideal_mesh", base, None)
    if ideal_path and not mesh_path:
        raise t.fail("'dish.ideal_mesh' needs 'dish.mesh'")
    D = F = None
    if t.has("diameter_m") or not mesh_path:
        D = t.number("diameter_m", lo=0.0, lo_open=True, unit="m")
        if D > 1000.0:
            raise t.fail(f"'dish.diameter_m' = {D:g} m is not a dish: is it in mm?")
    if t.has("focal_length_m") or not mesh_path:
        F = t.number("focal_length_m", lo=0.0, lo_open=True, unit="m")
        if F > 1000.0:
            raise t.fail(f"'dish.focal_length_m' = {F:g} m is not a dish: is it in mm?")
    size = D if D is not None else 100.0
    resolution = t.number("resolution_m", DEFAULT_RESOLUTION, lo=0.0, lo_open=True, unit="m")
    if resolution > size / 8:
        raise t.fail(f"'dish.resolution_m' = {resolution:g} m is coarser than D/8")
    if D is not None and mesh_path is None:
        area = math.pi * (D / 2) ** 2
        faces = 2.0 * area / resolution**2
        if faces > MAX_FACES:
            raise t.fail(f"'dish.resolution_m' = {resolution:g} m would make about "
                         f"{faces / 1e6:.0f} million triangles (at most {MAX_FACES / 1e6:.0f} "
                         f"million: resolution_m >= {math.sqrt(2 * area / MAX_FACES):.3g} m)")
    unit = t.number("mesh_unit_m", 1.0, lo=0.0, lo_open=True, unit="m")
    t.done()
    return Dish(D, F, resolution, mesh_path, ideal_path, unit)


def _panels(t: Table | None, dish: Dish) -> PanelLayout | None:
    if t is None:
        return None
    if not t.has("ring_edges_m") or not t.has("panels_per_ring"):
        raise t.fail("the panels table needs 'panels.ring_edges_m' and 'panels.panels_per_ring'")
    edges = t.numbers("ring_edges_m", min_length=2, lo=0.0, what=" (m)")
    counts = t.numbers("panels_per_ring", integer=True, min_length=1, lo=1)
    gap = t.number("gap_m", 0.0, lo=0.0, unit="m")
    if gap > 0.5:
        raise t.fail(f"'panels.gap_m' = {gap:g} m is wider than any panel gap: is it in mm?")
    if dish.diameter is not None and not math.isclose(edges[-1], dish.diameter / 2, rel_tol=1e-9):
        raise t.fail(f"'panels.ring_edges_m' must end at the rim D/2 = {dish.diameter / 2:g} m, "
                     f"got {edges[-1]:g}")
    phi0 = t.angle("phi0_deg", 0.0)
    t.done()
    try:
        layout = PanelLayout(edges, counts, gap, phi0)
    except ValueError as exc:
        raise t.fail(f"'panels': {exc}") from exc
    for ring in range(layout.n_rings):
        lo, hi = layout.radial_limits(ring)
        if hi - lo < 4 * gap or hi <= lo:
            raise t.fail(f"'panels.gap_m' = {gap:g} m leaves ring {ring} no panel area")
    return layout


def check_frequency(f: float, name: str) -> None:
    """Refuse a frequency (Hz) that is not a finite microwave one (1 MHz .. 10 THz)."""
    if not math.isfinite(f) or not f > 0:
        raise SceneError(f"{name} must be a finite frequency > 0 Hz, got {f:g}")
    if f < MIN_FREQUENCY_HZ:
        raise SceneError(f"{name} = {f:g} is in Hz: {f:g} Hz is not a microwave; "
                         f"for {f:g} GHz write {f * 1e9:g}")
    if f > MAX_FREQUENCY_HZ:
        raise SceneError(f"{name} = {f:g} Hz is above {MAX_FREQUENCY_HZ:g} Hz (10 THz): "
                         "not a radio telescope's frequency")




def _source(t: Table) -> Source:
    f = t.number("frequency_hz", unit="Hz")
    try:
        check_frequency(f, "'source.frequency_hz'")
    except SceneError as exc:
        raise t.fail(str(exc)) from exc
    theta = t.number("incidence_theta_deg", 0.0, lo=0.0, hi=90.0, hi_open=True, unit="deg")
    phi = t.number("incidence_phi_deg", 0.0, unit="deg")
    pol = t.number("polarization_deg", 0.0, unit="deg")
    t.done()
    return Source(f, math.radians(theta), math.radians(phi), math.radians(pol))


def _sphere(t: Table, dish: Dish) -> SphereGrid:
    R = t.number("radius_m", lo=0.0, lo_open=True, unit="m")
    if dish.focal_length is not None and R >= dish.focal_length:
        raise t.fail(f"'sphere.radius_m' = {R:g} m must be smaller than the focal length "
                     f"{dish.focal_length:g} m (the sphere would cut the dish)")
    n_theta = t.integer("n_theta", 90)
    n_phi = t.integer("n_phi", 360)
    try:
        check_sphere_cells(n_theta, n_phi, ("'sphere.n_theta'", "'sphere.n_phi'"))
    except SceneError as exc:
        raise t.fail(str(exc)) from exc
    t0 = t.number("theta_min_deg", 0.0, lo=0.0, unit="deg")
    t1 = t.number("theta_max_deg", 90.0, hi=90.0, unit="deg")
    if t1 <= t0:
        raise t.fail(f"'sphere.theta_max_deg' = {t1:g} must exceed theta_min_deg = {t0:g}")
    if dish.diameter is not None and dish.focal_length is not None:
        rim = math.degrees(theta_rim(dish.diameter, dish.focal_length))
        if t0 >= rim:
            raise t.fail(f"'sphere.theta_min_deg' = {t0:g} is beyond the rim image at "
                         f"{rim:.2f} deg: the sphere would see no reflection")
    p0 = t.number("phi_min_deg", 0.0, lo=-360.0, hi=360.0, unit="deg")
    p1 = t.number("phi_max_deg", p0 + 360.0, lo=-360.0, hi=720.0, unit="deg")
    if 360.0 < p1 - p0 <= 360.0 * (1.0 + 1e-12):  # a whole turn written from a phi_min with decimals
        p1 = p0 + 360.0
    if not 0 < p1 - p0 <= 360.0:
        raise t.fail("'sphere.phi_max_deg' - 'phi_min_deg' must lie in (0, 360]")
    t.done()
    return SphereGrid(R, n_theta, n_phi, math.radians(t0), math.radians(t1),
                      math.radians(p0), math.radians(p1))
