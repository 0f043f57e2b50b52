"""Scan plans from TOML: the sphere grid to measure, the order, averaging and drift references.

A plan names the reflector (F, D in m; frequency in Hz), the grid of cell centres (theta and phi
ranges and steps, degrees in the file, radians here), the acquisition settings and the rig file
(whose track radius is the sphere radius R). The order is fixed: one track sweep in theta per
phi line, phi ascending, the sweep direction alternating from line to line, and a reading at a
fixed reference position before the first line, after every K lines and after the last line
(to follow slow source and receiver drift). Every step has a global index; the journal and the
simulator's noise and drift are keyed by it.

A plan may name the obstacles in the telescope's beam (feed cabin, legs, any mesh) in the
``[[obstacle]]`` tables a scene takes (read by the scene's own parser,
:func:`raysim.scene.obstacles.obstacles_of`, in the reflector frame, metres). They do not
change what is measured, only how the scan is assembled: :attr:`ScanPlan.blocked_share` is
the share of each cell's GO power they take from the ideal paraboloid, the cells the measured
FieldMap marks ``blocked`` (:mod:`hardware.assemble`).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field, replace
from functools import cached_property, lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hardware.config import Table, plan_table, read_toml
from hardware.drift import DRIFT_MODES
from hardware.errors import PlanError
from hardware.rig import Rig, load_rig, rig_from_table
from hardware.sim.settings import SimSettings, sim_settings_from_table
from raysim.errors import SceneError
from raysim.files import find_input
from raysim.maps.probe import Probe
from raysim.maps.sphere import SphereGrid, theta_rim
from raysim.scene.obstacles import obstacles_of
from raysim.scene.scene import check_frequency, check_sphere_cells
from raysim.surface.obstacles import Obstacle, ObstacleMesh, obstacle_mesh

SAMPLE = "sample"
REFERENCE = "reference"


#: settings that bound how a step is reached, never what it reads (left out of a journal's
#: fingerprint): the instruments' addresses and read timeout, the axes' speed and move timeout,
#: and the simulated rig's time scale
NOT_READINGS = {"rig": ("resources", "speed", "move_timeout_s", "visa_timeout_s"),
                "extra": ("sim_time_scale",)}


@dataclass(frozen=True)
class Step:
    """One acquisition step: a grid cell (i along theta, j along phi) or a reference reading.

    ``theta``, ``phi`` are the commanded angles (rad); a reference step has i = j = -1.
    """

    index: int
    kind: str
    i: int
    j: int
    theta: float
    phi: float


@dataclass(frozen=True)
class ScanPlan:
    """A scan plan. Lengths in m, angles in rad, power in W, times in s.

    ``simulator`` holds the settings a simulated run starts from (the plan's
    ``[simulator]`` table). Each reference reading averages ``reference_samples`` readings;
    ``drift_correction`` (see :data:`DRIFT_MODES`) says how the reference readings correct
    the samples, ``drift_window`` how many references a ``smooth`` fit spans.
    ``power_unit`` is the power the receiver reads when the intensity is 1 (the incident
    plane wave's), so intensity = power / power_unit.
    ``reading_s`` is the power meter's time per reading (for the scan's duration).
    ``refer_to_sphere`` scales each reading by (r / R)^2, r the probe's distance from the
    focus per the rig's calibration, to refer it to the sphere of radius R (the rays of a
    focusing reflector converge on the focus). ``polarization`` (rad from x) is the incident
    wave's E, which a polarised probe's ideal reading depends on. ``obstacles``: what stands
    in the beam (the plan's ``[[obstacle]]`` tables, reflector frame, m), none by default.
    """

    focal_length: float
    diameter: float
    frequency_hz: float
    grid: SphereGrid
    rig: Rig
    settle_s: float = 0.0
    samples_per_point: int = 4
    reference_every: int = 4
    reference: tuple[float, float] = (0.0, 0.0)
    reference_samples: int = 64
    drift_correction: str = "auto"
    drift_window: int = 9
    power_unit: float = 1e-5
    refer_to_sphere: bool = True
    reading_s: float = 0.05
    simulator: SimSettings = field(default_factory=SimSettings)
    text: str = ""
    rig_text: str = ""
    files: tuple[Path, ...] = ()  # the plan file, its rig file and its obstacle mesh files
    polarization: float = 0.0
    obstacles: tuple[Obstacle, ...] = ()

    def inputs(self) -> list[tuple[str, Path]]:
        """(what, path) of the files this plan was read from, for output checks."""
        return [("plan or rig file" if f.suffix == ".toml" else "obstacle mesh file the plan names",
                 f) for f in self.files]

    def steps(self) -> list[Step]:
        """Every step of the scan in acquisition order (see the module docstring)."""
        theta, phi = self.grid.theta, self.grid.phi
        out: list[Step] = []

        def reference() -> None:
            out.append(Step(len(out), REFERENCE, -1, -1, *self.reference))

        reference()
        for j in range(self.grid.n_phi):
            order = range(self.grid.n_theta) if j % 2 == 0 else range(self.grid.n_theta - 1, -1, -1)
            for i in order:
                out.append(Step(len(out), SAMPLE, i, j, float(theta[i]), float(phi[j])))
            last_line = j == self.grid.n_phi - 1
            if (j + 1) % self.reference_every == 0 or last_line:
                reference()
        return out

    def fingerprint(self, extra: dict[str, Any] | None = None, legacy: bool = False) -> str:
        """A hash of everything that decides the samples (plan, rig, ``extra`` settings).

        The drift correction and the obstacles are left out: they only decide how the
        journal's readings are turned into a FieldMap, so they may change between a scan and
        its resumption. So are the settings of :data:`NOT_READINGS`, which bound how a step is
        reached and never what it reads: a crew may lengthen a timeout or slow an axis to get
        a stopped scan going again. ``legacy``: the fingerprint journals written before that
        recorded (those settings in), which a resume still accepts.
        """
        rig = asdict(self.rig)
        for key in ("resources",) if legacy else NOT_READINGS["rig"]:
            rig.pop(key)
        if self.rig.probe_response.ideal:
            rig.pop("probe_response")  # the journals of scans made before probes existed still match
        skip = ("text", "rig_text", "files", "rig", "simulator", "drift_correction",
                "drift_window", "reading_s", "obstacles") + (("polarization",) if self.polarization == 0.0
                                                else ())
        content = {k: v for k, v in asdict(self).items() if k not in skip}
        content["rig"] = rig
        content["extra"] = {k: v for k, v in (extra or {}).items()
                            if legacy or k not in NOT_READINGS["extra"]}
        blob = json.dumps(content, sort_keys=True, default=str).encode()
        return hashlib.sha256(blob).hexdigest()[:16]

    def duration(self, samples_per_point: int | None = None) -> float:
        """The scan's time (s) on the rig: every move at the axes' speed (both axes at once),
        the settle time after it and the readings (``samples_per_point``, default the plan's,
        at each cell; ``reference_samples`` at each reference)."""
        samples = self.samples_per_point if samples_per_point is None else samples_per_point
        moves, n_samples, n_references = self._motion
        readings = n_samples * samples + n_references * self.reference_samples
        return moves + (n_samples + n_references) * self.settle_s + readings * self.reading_s

    @cached_property
    def _motion(self) -> tuple[float, int, int]:
        """The time (s) the scan's moves take, and its sample and reference steps."""
        moves, here, n_samples, steps = 0.0, None, 0, self.steps()
        for step in steps:
            there = self.rig.axes(step.theta, step.phi)
            if here is not None:
                moves += max(abs(there[0] - here[0]), abs(there[1] - here[1])) / self.rig.speed
            here = there
            n_samples += step.kind == SAMPLE
        return moves, n_samples, len(steps) - n_samples

    @property
    def obstacle_mesh(self) -> ObstacleMesh | None:
        """The obstacles' triangles on this plan's dish (m, reflector frame), None without."""
        return _obstacle_mesh(self.obstacles, self.focal_length, _file_stamps(self.obstacles))

    @property
    def blocked_share(self) -> NDArray[np.float64] | None:
        """(n_theta, n_phi), read-only: the share of each cell's GO power the obstacles take
        from the ideal paraboloid as the rig's probe reads it, on the plan's grid (None
        without obstacles); traced as the inversion's GO model traces it
        (:func:`raysim.optics.blocked_cells.paraboloid_blocked_share`), once per geometry (a plan
        copied with other acquisition settings shares it)."""
        if not self.obstacles:
            return None
        probe = self.rig.probe_response
        return _blocked_share(self.grid, self.focal_length, self.diameter, self.obstacles,
                              None if probe.ideal else probe, self.polarization,
                              _file_stamps(self.obstacles))

    def check_reach(self) -> None:
        """Raise :class:`PlanError` if a step lies outside the rig's reach."""
        for step in self.steps():
            self.rig.axes(step.theta, step.phi)

    def check_tolerance(self) -> None:
        """Raise :class:`PlanError` unless the rig's move tolerance (rad) is below half the
        plan's smallest grid step (rad), theta's or phi's (each axis moves by its step).

        A move accepted up to half a step off its target reads the probe nearer the next
        cell's centre than its own: with tolerance_deg 5 under 4 deg steps a move stalled
        2 deg short was journaled into its cell, exit 0. A scan is refused before any motion;
        a journal made already is still read (``--from-journal``).
        """
        step = min(self.grid.dtheta, self.grid.dphi)
        if self.rig.tolerance >= 0.5 * step:
            raise PlanError(f"the rig's tolerance_deg {math.degrees(self.rig.tolerance):g} deg "
                            f"is not below half the plan's smallest grid step "
                            f"({math.degrees(step):g} deg / 2 = {math.degrees(0.5 * step):g} "
                            "deg): a move that far off its target would be stored in the wrong "
                            f"cell; set [motion] tolerance_deg below {math.degrees(0.5 * step):g}")


def _file_stamps(obstacles: tuple[Obstacle, ...]) -> tuple:
    """(path, size, mtime in ns) of each mesh obstacle's file: part of the caches' keys, so a
    file edited while the process runs is read again."""
    stamps = []
    for obstacle in obstacles:
        path = getattr(obstacle, "path", None)
        if path is not None and Path(path).is_file():
            stat = Path(path).stat()
            stamps.append((str(path), stat.st_size, stat.st_mtime_ns))
    return tuple(stamps)


@lru_cache(maxsize=4)
def _obstacle_mesh(obstacles: tuple[Obstacle, ...], F: float,
                   stamps: tuple = ()) -> ObstacleMesh | None:
    """:func:`raysim.surface.obstacles.obstacle_mesh`, kept for the last few plans (``stamps``:
    :func:`_file_stamps` of the obstacles, keying the cache only)."""
    return obstacle_mesh(obstacles, F)


@lru_cache(maxsize=4)
def _blocked_share(grid: SphereGrid, F: float, D: float, obstacles: tuple[Obstacle, ...],
                   probe: Probe | None, polarization: float,
                   stamps: tuple = ()) -> NDArray[np.float64]:
    """:func:`raysim.optics.blocked_cells.paraboloid_blocked_share` of one plan geometry, kept
    (read-only) for the last few: the trace takes seconds on a large dish (``stamps`` as
    :func:`_obstacle_mesh`)."""
    from raysim.optics.blocked_cells import paraboloid_blocked_share

    mesh = _obstacle_mesh(obstacles, F, stamps)
    if mesh is None:
        raise PlanError("no obstacles to trace")
    share = paraboloid_blocked_share(grid, F, D, mesh, probe, polarization)
    share.setflags(write=False)
    return share


def load_plan(path: str | Path, rig: str | Path | None = None) -> ScanPlan:
    """Read a scan plan; ``rig`` (a rig.toml) overrides the plan's own ``rig`` entry."""
    data, text, path = read_toml(path, "scan plan")
    plan = plan_from_table(plan_table(data, str(path)), text, path.parent, rig)
    return replace(plan, files=(path, *plan.files))


def plan_from_table(top: Table, text: str = "", base: Path = Path("."),
                    rig_path: str | Path | None = None) -> ScanPlan:
    """Build a :class:`ScanPlan` from a parsed plan table; relative paths start at ``base``."""
    top.string("description", "")  # for the reader (and raysim scenes)
    rig_entry = top.data.get("rig")
    top.used.add("rig")
    rig_file = None
    if rig_path is not None:
        rig_file = find_input(rig_path)
        rig, rig_text = load_rig(rig_file)
    elif isinstance(rig_entry, str):
        rig_file = find_input(rig_entry, base)
        rig, rig_text = load_rig(rig_file)
    elif isinstance(rig_entry, dict):
        rig, rig_text = rig_from_table(plan_table(rig_entry, top.source, "rig")), ""
    else:
        raise top.fail("'rig' must name a rig file or be a [rig] table")

    refl = top.sub("reflector", required=True)
    F = refl.number("focal_length_m", lo=0.0, lo_open=True)
    D = refl.number("diameter_m", lo=0.0, lo_open=True)
    frequency_hz = refl.number("frequency_hz", lo=0.0, lo_open=True)
    polarization = refl.angle("polarization_deg", 0.0, lo=-360.0, hi=360.0)
    refl.done()
    try:  # the range of every frequency raysim reads
        check_frequency(frequency_hz, "'reflector.frequency_hz'")
    except SceneError as exc:
        raise top.fail(str(exc)) from exc
    if rig.radius >= F:
        raise top.fail(f"the track radius {rig.radius:g} m must be below F = {F:g} m")

    g = top.sub("grid", required=True)
    theta_lo, theta_hi = g.angle("theta_min_deg", 0.0, lo=0.0), g.angle("theta_max_deg", hi=90.0)
    phi_lo = g.angle("phi_min_deg", 0.0, lo=-360.0, hi=360.0)
    phi_hi = g.angle("phi_max_deg", 360.0, lo=-360.0, hi=720.0)
    n_theta = _cells(g, "theta", theta_lo, theta_hi)
    n_phi = _cells(g, "phi", phi_lo, phi_hi)
    g.done()
    if phi_hi - phi_lo > 2 * math.pi + 1e-9:
        raise g.fail("'grid': the phi range exceeds 360 deg")
    if theta_lo >= theta_rim(D, F) - 1e-12:  # refused before hours of scanning, not after
        raise g.fail(f"'grid' starts at theta {math.degrees(theta_lo):g} deg, beyond the rim image "
                     f"(theta {math.degrees(theta_rim(D, F)):.4g} deg for D = {D:g} m, F = {F:g} m): "
                     "the dish lights none of its cells")
    try:  # the same caps as a scene's sphere: a plan's points are its cells
        check_sphere_cells(n_theta, n_phi, ("'grid' theta cells", "phi cells"))
    except SceneError as exc:
        raise g.fail(f"{exc}: coarser steps") from exc
    grid = SphereGrid(rig.radius, n_theta, n_phi, theta_lo, theta_hi, phi_lo, phi_hi)

    acq = top.sub("acquisition", required=False)
    settle_s = acq.number("settle_s", 0.0, lo=0.0, hi=3600.0)
    samples = acq.integer("samples_per_point", 4, lo=1)
    every = acq.integer("reference_every_lines", 4, lo=1)
    reference = (acq.angle("reference_theta_deg", 0.0, lo=0.0, hi=90.0),
                 acq.angle("reference_phi_deg", 0.0, lo=-360.0, hi=360.0))
    power_unit_dbm = acq.number("power_unit_dbm", -20.0, lo=-150.0, hi=60.0)
    reference_samples = acq.integer("reference_samples", 64, lo=1)
    drift = acq.string("drift_correction", "auto", choices=DRIFT_MODES)
    window = acq.integer("drift_window", 9, lo=2)
    refer = acq.boolean("refer_to_sphere", True)
    reading_s = acq.number("reading_s", 0.05, lo=0.0, hi=60.0)
    acq.done()

    simulator = sim_settings_from_table(top.sub("simulator", required=False))
    obstacles = obstacles_of(top.tables("obstacle"), D, F, base)
    top.done()

    plan = ScanPlan(F, D, frequency_hz, grid, rig, settle_s, samples, every, reference,
                    reference_samples, drift, window, dbm_to_w(power_unit_dbm), refer,
                    reading_s, simulator, text, rig_text,
                    ((rig_file,) if rig_file is not None else ()) + tuple(top.files),
                    polarization, obstacles)
    plan.check_reach()
    _check_reference_lit(plan, acq)
    return plan


#: a drift reference whose cell loses more than this share of its GO power to the obstacles
#: reads their shadow, not the beam
REFERENCE_BLOCKED_SHARE = 0.5


def _check_reference_lit(plan: ScanPlan, acq: Table) -> None:
    """Refuse a drift reference that cannot see the dish's beam, unless drift is not
    corrected: beyond the rim image, or in the obstacles' shadow. Its readings would be the
    receiver's floor, and the corrections taken from them would scale every line by noise (a
    simulated floor even followed the simulated gain, so the scan looked corrected)."""
    if plan.drift_correction == "none":
        return
    theta, phi = plan.reference
    where = f"the drift reference (theta {math.degrees(theta):g}, phi {math.degrees(phi):g} deg)"
    remedy = ("move it into the lit beam (acquisition.reference_theta_deg, reference_phi_deg) or "
              'set acquisition.drift_correction = "none"')
    rim = theta_rim(plan.diameter, plan.focal_length)
    if theta >= rim:
        raise acq.fail(f"{where} lies beyond the rim image (theta {math.degrees(rim):.4g} deg): it "
                       f"reads no beam; {remedy}")
    if not plan.obstacles:
        return
    g = plan.grid
    i = int(np.searchsorted(g.theta_edges, theta, side="right")) - 1
    j = int(np.searchsorted(g.phi_edges, g.phi_edges[0] + (phi - g.phi_edges[0]) % (2 * np.pi),
                            side="right")) - 1
    if 0 <= i < g.n_theta and 0 <= j < g.n_phi:  # the grid's own marks, which the scan needs anyway
        share = float(plan.blocked_share[i, j])
    else:  # a cell of the grid's size about the reference, traced alone
        half_theta = 0.5 * min(g.theta_edges[1] - g.theta_edges[0], rim - theta)
        half_phi = 0.5 * (g.phi_edges[1] - g.phi_edges[0])
        lo = max(theta - half_theta, 0.0)
        cell = SphereGrid(g.radius, 1, 1, lo, lo + 2 * half_theta, phi - half_phi, phi + half_phi)
        probe = plan.rig.probe_response
        share = float(_blocked_share(cell, plan.focal_length, plan.diameter, plan.obstacles,
                                     None if probe.ideal else probe, plan.polarization,
                                     _file_stamps(plan.obstacles))[0, 0])
    if share > REFERENCE_BLOCKED_SHARE:
        raise acq.fail(f"{where} lies in the obstacles' shadow ({100 * share:.0f} % of its GO power "
                       f"blocked): it would read the receiver's floor, not the beam; {remedy}")


def dbm_to_w(p_dbm: float) -> float:
    """Power in W from dBm (the instrument's unit)."""
    return 1e-3 * 10.0 ** (p_dbm / 10.0)


def w_to_dbm(p_w: float) -> float:
    """Power in dBm from W."""
    return 10.0 * math.log10(p_w / 1e-3)


def _cells(g: Table, name: str, lo: float, hi: float) -> int:
    """Number of cells from ``<name>_step_deg``; the range must hold a whole number of them."""
    step = g.angle(f"{name}_step_deg", lo=0.0, lo_open=True)
    if hi <= lo:
        raise g.fail(f"'grid.{name}_max_deg' must be above {name}_min_deg")
    n = (hi - lo) / step
    if abs(n - round(n)) > 1e-6 or round(n) < 1:
        raise g.fail(f"'grid': the {name} range must hold a whole number of "
                        f"{math.degrees(step):g} deg steps")
    return round(n)
