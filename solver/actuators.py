"""Actuator layouts: where the actuators under the panels sit and which panels each one moves.

Frame: the aperture plane (x, y) of docs/physics.md (m), displacements along z (m). Sign
convention, stated once here and in every file :mod:`solver.correction_io` writes: a positive
command moves the surface at that actuator along +z, away from the vertex and toward the focus.

A layout is a table of actuators (id, x, y, optional stroke range) and, for every panel of a
:class:`raysim.surface.panels.PanelLayout`, its *support points*: (actuator index, x, y), the
aperture point (m) where that actuator holds the panel. A panel takes the shape that
interpolates the commands at its k support points with the first k of the monomials 1, s, t,
s t, s^2, t^2 in the panel's own Cartesian frame (s along the panel's mid radius, t across it,
both from the panel centroid and in units of the square root of its area): a piston for one,
a plane for three (the rigid body: the ``screws`` layout with its three screws, a wedge held
at its apex and two outer corners), the bilinear shape through the four corners of a panel in
the ``corners`` layout. An actuator shared by neighbouring panels (a corner common to up to
four panels) moves every panel it holds, with the same stroke.
"""

from __future__ import annotations

import csv
import functools
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from solver.errors import SolverError

#: monomials in the panel frame (s, t) a panel's shape is built from, in the order they are taken
MONOMIALS = ((0, 0), (1, 0), (0, 1), (1, 1), (2, 0), (0, 2))
#: the most a panel point may move per unit of its actuators' largest stroke (the sum of its
#: shape functions' magnitudes there). On the 110 m dish's 60 panels: the corner layout 1.1 to
#: 1.3, the default screws 3 to 9, a third screw a tenth of the panel's size off the line of
#: the other two 12; 1.2 mm off it (a typing slip on a 12 m panel) over 10^4, and that one
#: panel's near-singular shape wiped out the commands on every other panel
MAX_LEVER = 1000.0
#: default screw positions (u, v) of the ``screws`` layout: three screws, a rigid body
DEFAULT_SCREWS = ((0.2, 0.2), (0.2, 0.8), (0.8, 0.5))


class ActuatorError(SolverError):
    """An actuator layout is unusable (outside the dish, a panel nothing holds, a bad file)."""


@dataclass(frozen=True)
class ActuatorLayout:
    """Actuators (``ids``, positions ``xy`` (n, 2) m, stroke ``ranges`` (n, 2) m or None) and per
    panel the support points ``supports[p]`` = ((actuator index, x, y), ...)."""

    ids: tuple[str, ...]
    xy: NDArray[np.float64]
    supports: tuple[tuple[tuple[int, float, float], ...], ...]
    ranges: NDArray[np.float64] | None = None
    kind: str = "file"

    @property
    def n_actuators(self) -> int:
        return len(self.ids)

    def panels_of(self, actuator: int) -> list[int]:
        """Panel ids ``actuator`` (an index) moves."""
        return [p for p, sup in enumerate(self.supports) if any(a == actuator for a, _, _ in sup)]

    def shape_description(self) -> str:
        counts = sorted({len(s) for s in self.supports})
        names = {1: "piston", 2: "piston + radial slope", 3: "rigid body (a plane through 3 points)",
                 4: "bilinear (1, s, t, s t) through 4 points"}
        return "; ".join(f"{c} per panel: {names.get(c, f'{c}-point polynomial')}" for c in counts)


def local_st(layout, panel: int, x, y) -> tuple[NDArray, NDArray]:
    """The panel's own Cartesian coordinates (s, t) of aperture points (x, y) (m): from the
    panel centroid, s along its mid radius and t across it, in units of sqrt(panel area)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    phi_a, phi_b = layout.angular_limits(panel)
    mid = 0.5 * (phi_a + phi_b)
    cx, cy = layout.centres()[panel]
    scale = np.sqrt(max(layout.panel_area(panel), 1e-12))
    dx, dy = x - cx, y - cy
    return (dx * np.cos(mid) + dy * np.sin(mid)) / scale, (-dx * np.sin(mid) + dy * np.cos(mid)) / scale


def _xy(layout, panel: int, u: float, v: float) -> tuple[float, float]:
    ring = int(layout.ring(panel))
    r_in, r_out = layout.ring_edges[ring], layout.ring_edges[ring + 1]
    phi_a, phi_b = layout.angular_limits(panel)
    r, phi = r_in + u * (r_out - r_in), phi_a + v * (phi_b - phi_a)
    return r * np.cos(phi), r * np.sin(phi)


def _merge(points: list[tuple[int, float, float, float, float]], layout, prefix: str,
           tol: float = 1e-6) -> ActuatorLayout:
    """Actuators from (panel, u, v, x, y) points; points within ``tol`` (m) are one actuator,
    held once per panel."""
    xy: list[tuple[float, float]] = []
    index: dict[tuple[int, int], int] = {}
    supports: list[list[tuple[int, float, float]]] = [[] for _ in range(layout.n_panels)]
    for panel, _u, _v, x, y in points:
        key = (round(x / tol), round(y / tol))
        if key not in index:
            index[key] = len(xy)
            xy.append((x, y))
        if all(a != index[key] for a, _, _ in supports[panel]):
            supports[panel].append((index[key], x, y))
    ids = tuple(f"{prefix}{i:04d}" for i in range(len(xy)))
    return ActuatorLayout(ids, np.array(xy, dtype=np.float64).reshape(-1, 2),
                          tuple(tuple(s) for s in supports), kind=prefix.rstrip("-"))


def corners_layout(layout) -> ActuatorLayout:
    """One actuator at every panel corner, shared by the panels that meet there (gaps ignored:
    the corner is where the cut lines cross). Every ring must be cut into >= 2 panels."""
    points = []
    for panel in range(layout.n_panels):
        if layout.panels_per_ring[int(layout.ring(panel))] < 2:
            raise ActuatorError(f"panel {panel} fills its whole ring: it has no corners, so the "
                                "corners layout holds it nowhere (give --actuators)")
        for u in (0.0, 1.0):
            for v in (0.0, 1.0):
                x, y = _xy(layout, panel, u, v)
                points.append((panel, u, v, x, y))
    return _merge(points, layout, "corner-")


def screws_layout(layout, positions=DEFAULT_SCREWS) -> ActuatorLayout:
    """Screws at (u, v) on every panel, one panel each: u = (r - r_in) / (r_out - r_in) across
    the ring, v = (phi - phi_a) / (phi_b - phi_a) along it, each in [0, 1]."""
    if not 1 <= len(positions) <= len(MONOMIALS):
        raise ActuatorError(f"{len(positions)} screws per panel: give 1 to {len(MONOMIALS)} (a "
                            "panel's shape has at most that many terms)")
    points = []
    for panel in range(layout.n_panels):
        for u, v in positions:
            if not (0.0 <= u <= 1.0 and 0.0 <= v <= 1.0):
                raise ActuatorError(f"screw position (u={u:g}, v={v:g}) lies outside its panel")
            x, y = _xy(layout, panel, u, v)
            points.append((panel, u, v, x, y))
    # screws are never shared: a distinct tolerance key per panel
    acts = ActuatorLayout(tuple(f"screw-{p:04d}-{k}" for p in range(layout.n_panels)
                                for k in range(len(positions))),
                          np.array([(x, y) for _, _, _, x, y in points]).reshape(-1, 2),
                          tuple(tuple((p * len(positions) + k, *_xy(layout, p, u, v))
                                      for k, (u, v) in enumerate(positions))
                                for p in range(layout.n_panels)), kind="screws")
    return acts


ACTUATOR_KEYS = ("id", "x_m", "y_m", "panels", "min_m", "max_m")
#: columns ``raysim correct`` writes beside the actuators' own (read back, not used)
WRITTEN_KEYS = ("command_", )


def read_actuators(path: str | Path, layout) -> ActuatorLayout:
    """Read actuators from a CSV (columns id, x_m, y_m, panels, and optional min_m, max_m;
    ``panels`` the panel ids separated by spaces or ';') or a TOML file (``[[actuator]]`` tables
    with the same keys, ``panels`` a list). Positions in metres in the aperture plane. The
    commands files ``raysim correct`` writes read back as actuator files (their command
    columns are skipped); any other column or key is refused, as a misspelt range would
    otherwise go unseen."""
    path = Path(path)
    if path.is_dir():
        raise ActuatorError(f"{path}: is a folder, give an actuator file (CSV or TOML)")
    try:
        # utf-8-sig: a spreadsheet's "CSV UTF-8" starts with a byte-order mark, which made the
        # first column "\ufeffid", refused as unknown under a name that printed as "id"
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise ActuatorError(f"{path}: {exc.strerror}") from exc
    except UnicodeDecodeError:
        raise ActuatorError(f"{path}: not a text file (an actuator file is CSV or TOML, UTF-8)") from None
    try:
        if path.suffix.lower() == ".toml":
            rows = _toml_rows(tomllib.loads(text), path)
        else:
            reader = csv.DictReader(line for line in text.splitlines()
                                    if not line.lstrip().startswith("#"))
            rows = list(reader)
            names = [str(n).strip() for n in reader.fieldnames or ()]
            twice = sorted({n for n in names if names.count(n) > 1})
            if twice:  # DictReader keeps the last: a second, empty max_m lifted the limit
                raise ActuatorError(f"{path}: column {', '.join(twice)} appears twice")
    except (tomllib.TOMLDecodeError, csv.Error) as exc:
        raise ActuatorError(f"{path}: unreadable actuator file ({exc})") from exc
    if not rows:
        raise ActuatorError(f"{path}: no actuators (CSV columns id,x_m,y_m,panels or TOML "
                            "[[actuator]] tables)")
    ids, xy, ranges, members = [], [], [], []
    for k, row in enumerate(rows):
        unknown = [str(key) for key in row if key not in ACTUATOR_KEYS
                   and not str(key).startswith(WRITTEN_KEYS)]
        if unknown:
            raise ActuatorError(f"{path}: actuator row {k + 1} has unknown "
                                f"{'key' if path.suffix.lower() == '.toml' else 'column'} "
                                f"{', '.join(unknown)} (known: {', '.join(ACTUATOR_KEYS)})")
        where = f"{path}: actuator row {k + 1}"
        try:
            ids.append(str(row["id"]))
            if not ids[-1].strip():  # a command nobody can address
                raise ActuatorError(f"{where}: its id is empty; give every actuator the id the "
                                    "rig knows it by")
            if ids[-1].lstrip().startswith("#"):  # commands.csv would read back as a comment
                raise ActuatorError(f"{where}: id {ids[-1]!r} starts with '#', which marks a "
                                    "comment line in these files")
            xy.append((_number(row["x_m"], "x_m", where), _number(row["y_m"], "y_m", where)))
            members.append(_panel_ids(row["panels"], where))
            if not members[-1]:  # commanded 0, and its panels' shape silently another
                raise ActuatorError(f"{where} (actuator {ids[-1]}): its panels are empty; name "
                                    "the panels it moves")
            lo, hi = row.get("min_m"), row.get("max_m")
            ranges.append((-np.inf if lo in (None, "") else _number(lo, "min_m", where),
                           np.inf if hi in (None, "") else _number(hi, "max_m", where)))
        except ActuatorError:
            raise
        except (KeyError, ValueError, TypeError) as exc:
            raise ActuatorError(f"{where} needs id, x_m, y_m, panels "
                                f"(numbers; panels as ids): {exc}") from exc
        if any(math.isnan(v) for v in ranges[-1]):
            raise ActuatorError(f"{path}: actuator {ids[-1]}: min_m and max_m must be numbers "
                                "(leave them out for an unbounded actuator)")
    return build_layout(ids, np.array(xy), members, np.array(ranges), layout, str(path))


def _number(value, key: str, where: str) -> float:
    """A position or range (m) from a CSV cell or a TOML value; a TOML boolean is no number
    (``float(True)`` would silently be 1 m)."""
    if isinstance(value, bool):
        raise ActuatorError(f"{where}: {key} = {str(value).lower()} is a boolean, give a number in metres")
    return float(value)


def _panel_ids(panels, where: str) -> list[int]:
    """Panel ids from a CSV cell ("3 4" or "3;4") or a TOML list of integers; booleans and
    fractional numbers are refused (``int(True)`` is panel 1, ``int(6.5)`` panel 6)."""
    if isinstance(panels, str):
        ids = [int(p) for p in panels.replace(";", " ").split()]
    elif not isinstance(panels, list):
        raise ActuatorError(f"{where}: panels must be a list of panel ids, got {panels!r}")
    else:
        bad = [p for p in panels if isinstance(p, bool) or not isinstance(p, int)]
        if bad:
            raise ActuatorError(f"{where}: panels must be integer panel ids, got {bad[0]!r}")
        ids = list(panels)
    twice = sorted({p for p in ids if ids.count(p) > 1})
    if twice:  # counted twice, a panel's 3 actuators read as "its 6 do not fix a panel shape"
        raise ActuatorError(f"{where}: panel {twice[0]} is named twice in its panels")
    return ids


def _toml_rows(data: dict, path: Path) -> list:
    """The ``[[actuator]]`` tables of an actuator TOML file; top-level keys the commands file
    writes (unit, RMS before and after, warnings) are allowed, any other is refused."""
    unknown = [key for key in data if key not in ("actuator", "unit", "warnings")
               and not key.startswith("rms_")]
    if unknown:
        raise ActuatorError(f"{path}: unknown top-level key {', '.join(unknown)} (actuators go in "
                            "[[actuator]] tables)")
    rows = data.get("actuator", [])
    if not isinstance(rows, list) or not all(isinstance(row, dict) for row in rows):
        raise ActuatorError(f"{path}: 'actuator' must be an array of tables ([[actuator]])")
    return rows


def build_layout(ids, xy, members, ranges, layout, source: str = "actuators") -> ActuatorLayout:
    """Check and assemble actuators given by position and the panels each moves."""
    if len(set(ids)) != len(ids):
        raise ActuatorError(f"{source}: actuator ids repeat")
    rim = layout.rim_radius
    for name, (x, y) in zip(ids, xy, strict=True):
        # a micrometre of slack: positions written to the micrometre read back inside
        if not np.isfinite(x) or not np.isfinite(y) or np.hypot(x, y) > rim * (1 + 1e-9) + 1e-6:
            raise ActuatorError(f"{source}: actuator {name} at ({x:g}, {y:g}) m lies outside the "
                                f"dish (rim radius {rim:g} m)")
    supports: list[list[tuple[int, float, float]]] = [[] for _ in range(layout.n_panels)]
    for a, panels in enumerate(members):
        for p in panels:
            if not 0 <= p < layout.n_panels:
                raise ActuatorError(f"{source}: actuator {ids[a]} names panel {p}; the layout has "
                                    f"panels 0..{layout.n_panels - 1}")
            _check_on_panel(layout, p, ids[a], float(xy[a, 0]), float(xy[a, 1]), source)
            supports[p].append((a, float(xy[a, 0]), float(xy[a, 1])))
    for p, sup in enumerate(supports):
        if not sup:
            raise ActuatorError(f"{source}: panel {p} is held by no actuator")
        if len(sup) > len(MONOMIALS):
            raise ActuatorError(f"{source}: panel {p} has {len(sup)} actuators; at most "
                                f"{len(MONOMIALS)} are supported")
    _check_ranges(ids, ranges, source)
    bounded = np.isfinite(ranges).any()
    return ActuatorLayout(tuple(ids), np.asarray(xy, dtype=np.float64),
                          tuple(tuple(s) for s in supports), ranges if bounded else None)


def _check_ranges(ids, ranges: NDArray[np.float64], source: str) -> None:
    """Each stroke range (m) must be [min_m, max_m] with min_m <= 0 <= max_m: a command is a
    stroke from where the actuator stands now, 0."""
    for name, (lo, hi) in zip(ids, ranges, strict=True):
        if lo > hi:
            raise ActuatorError(f"{source}: actuator {name}: min_m = {lo:g} exceeds max_m = {hi:g}")
        if lo > 0 or hi < 0:
            raise ActuatorError(f"{source}: actuator {name}: its range [{lo:g}, {hi:g}] m excludes 0 "
                                "(a command is a stroke from the present position: min_m <= 0 <= max_m)")


def panel_distance(layout, panel: int, x: float, y: float) -> float:
    """Distance (m) from the aperture point (x, y) (m) to ``panel``'s outline between its cut
    lines (gaps not taken off): 0 on the panel, its edges and corners."""
    r = math.hypot(x, y)
    ring = int(layout.ring(panel))
    r_in, r_out = layout.ring_edges[ring], layout.ring_edges[ring + 1]
    radial = max(r_in - r, r - r_out, 0.0)
    phi_a, phi_b = layout.angular_limits(panel)
    if layout.panels_per_ring[ring] == 1 or r == 0.0:
        return radial
    if (math.atan2(y, x) - phi_a) % (2.0 * math.pi) <= phi_b - phi_a:
        return radial
    # outside the panel's angles (a sector of at most pi): the nearest point is on a cut line
    out = math.inf
    for phi in (phi_a, phi_b):
        along = min(max(x * math.cos(phi) + y * math.sin(phi), r_in), r_out)
        out = min(out, math.hypot(x - along * math.cos(phi), y - along * math.sin(phi)))
    return out


def _check_on_panel(layout, panel: int, name: str, x: float, y: float, source: str) -> None:
    """An actuator holds only panels it lies on or at the edge or corner of: within 2 cm plus 1 %
    of the panel's size (sqrt of its area, m); a wrong panel id in a file is refused here."""
    ring = int(layout.ring(panel))
    r_in, r_out = layout.ring_edges[ring], layout.ring_edges[ring + 1]
    size = math.sqrt(math.pi * (r_out**2 - r_in**2) / layout.panels_per_ring[ring])
    d = panel_distance(layout, panel, x, y)
    if d > 0.02 + 0.01 * size:
        raise ActuatorError(f"{source}: actuator {name} at ({x:g}, {y:g}) m is {d:.3g} m from panel "
                            f"{panel}, which it is said to hold (an actuator holds the panels it "
                            "lies on or at the edge or corner of)")


def shape_functions(layout, panel: int, support: tuple[tuple[int, float, float], ...],
                    x, y) -> NDArray[np.float64]:
    """Weights (len(x), k) of the k support points of ``panel`` at aperture points (x, y) (m): the
    interpolant in the first k monomials of :data:`MONOMIALS` of the panel frame (s, t).
    Raises when the points do not fix such a shape."""
    k = len(support)
    V_inv = _support_inverse(layout, panel, tuple((float(p[1]), float(p[2])) for p in support))
    s, t = local_st(layout, panel, x, y)
    M = np.stack([s**i * t**j for i, j in MONOMIALS[:k]], axis=-1)  # (points, k monomials)
    W = M @ V_inv
    lever = float(np.abs(W).sum(axis=1).max(initial=0.0))
    if lever > MAX_LEVER:
        raise ActuatorError(f"panel {panel}: its {k} actuators almost fail to fix a panel shape "
                            f"(nearly collinear or coincident): strokes of 1 um would move the "
                            f"panel by up to {lever:.0f} um; move them apart")
    return W


@functools.lru_cache(maxsize=4096)
def _support_inverse(layout, panel: int, points: tuple[tuple[float, float], ...]) -> NDArray[np.float64]:
    """The inverse of the monomials' values at a panel's support points (x, y) (m): the shape
    functions at any points are their monomials times it. Kept per support, because a
    deformation made of strokes (:func:`solver.correction.displacement`) is evaluated a few
    points at a time by a ray trace."""
    k = len(points)
    ps, pt = local_st(layout, panel, [p[0] for p in points], [p[1] for p in points])
    V = np.stack([ps**i * pt**j for i, j in MONOMIALS[:k]], axis=-1)  # (k points, k monomials)
    if np.linalg.matrix_rank(V) < k:
        raise ActuatorError(f"panel {panel}: its {k} actuators do not fix a panel shape "
                            "(collinear or coincident)")
    V_inv = np.linalg.inv(V)
    V_inv.flags.writeable = False
    return V_inv
