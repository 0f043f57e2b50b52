"""What ``raysim check`` runs on: the dish (a scene, or a mesh file fitted to a paraboloid),
the deformation it tests with, the panel gaps, and the wave engine per frequency.

Frame and units: the reflector frame of docs/physics.md (vertex at the origin, axis +z); lengths
in m, frequencies in Hz, angles in rad. Every defect a user can cause raises
:class:`CheckError` with one line, before any simulation starts.

The engine rule (:func:`choose_wave`; :data:`ENGINE_RULE` states it on the page): PO + PTD (rim)
is the reference wave engine at every frequency where its samples fit this machine's memory
(``simulate``'s cap, :func:`raysim.simulate.max_po_samples`); beyond it, go+edge, whose cost does
not grow as f^2. Its cost is not a reason to leave it: with the fast radiator the paper's dish
takes 48 s at 3 GHz and 9 minutes at 12 GHz on two cores, and the check says what it expects to
take (:func:`expected_seconds`, from the sums' cost as the chosen radiator runs them,
:func:`raysim.optics.fast.radiator.quadrature_cost`) before it starts, so a user who wants it
quicker forces ``--wave go+edge``. docs/engines.md has the measured accuracies behind the
order: go+edge agrees with PO + PTD to 0.006 to 0.6 % in the ideal intensity everywhere, and in
FA to 0.2 to 4.7 % of FA's RMS once the dish is a few hundred wavelengths across (the paper's
dish at 3 to 12 GHz, a 25 m dish at 1 and 3 GHz), but only to 21 to 59 % on the paper's dish at
0.3 and 1 GHz; on a user's own mesh, with its gaps, no one has measured it, which is what the
check is for.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from raysim.errors import RaysimError
from raysim.maps.aperture import ApertureGrid
from raysim.scene.scene import Scene, check_frequency, check_sphere_cells, load_scene, parse_scene
from raysim.surface.deformation import Deformation, NoDeformation, Sum
from raysim.surface.panels import PanelLayout

#: the engine rule as the check's page and dataset state it (plain text)
ENGINE_RULE = ("PO + PTD (rim) is the reference wave engine at every frequency where its samples "
               "fit this machine's memory (simulate's cap); beyond it, go+edge, whose cost does not "
               "grow as f^2. The check states the time it expects before it starts; --wave go+edge "
               "is the quick alternative. go+edge agrees with PO + PTD to 0.006 to 0.6 % in the "
               "ideal intensity, and in FA to 0.2 to 4.7 % of FA's RMS once the dish is a few "
               "hundred wavelengths across, but only to 21 to 59 % on the paper's dish at 0.3 and "
               "1 GHz (docs/engines.md).")

MESH_SUFFIXES = (".stl", ".ply", ".obj", ".glb", ".gltf", ".off")
WAVE_CHOICES = ("auto", "po", "po+ptd", "go+edge")
DEFORMATIONS = ("auto", "scene", "mix")
DEFAULT_RMS_M = 100e-6
#: pair evaluations a second per CPU thread (the units of the fast radiator's cost estimate), for
#: the time a check states before it starts: PO + PTD of both reflectors of the paper's dish on
#: 90 x 360 points took 48 s at 3 GHz (1.1e10), 156 s at 6 GHz (3.9e10) and 553 s at 12 GHz
#: (1.4e11) on two cores, 1.1e8 to 1.3e8 a thread
PAIRS_PER_SECOND_PER_THREAD = 1.2e8
WAVE_FACE_M = 4.0  # quadrature faces of the wave data (the refinement's PO model uses 5 m)
MESH_UNIT_OPTION = "--mesh-unit"  # how check's user scales a bare mesh file's coordinates
SPHERE_RADIUS_OF_F = 0.3  # a mesh's probe sphere by default: R = 0.3 F (the paper's 10 / 33)
MAX_FREQUENCIES = 12


class CheckError(RaysimError, ValueError):
    """A ``raysim check`` input that cannot be honoured (one line for the user)."""


@dataclass(frozen=True)
class Dish:
    """The dish a check runs on: the GO scene (the dish as given), the wave scene (the same
    dish on quadrature faces for a generated mesh; the same mesh for a mesh file), where the
    dish came from and how it was fitted."""

    go: Scene
    wave: Scene
    source: str  # the scene (also one whose [dish] names a mesh) or the bare mesh file given
    is_mesh: bool
    fit_rms: float = 0.0  # m, the mesh's RMS departure from its best-fit paraboloid
    notes: tuple[str, ...] = ()
    warning: str = ""  # what the user should know before trusting the check (a mesh in mm)
    pieces: int = 0  # a mesh's connected pieces (its panels); 0 for a generated dish

    @property
    def D(self) -> float:
        return self.go.D

    @property
    def F(self) -> float:
        return self.go.F


def is_mesh(source: str | Path) -> bool:
    return Path(source).suffix.lower() in MESH_SUFFIXES


def load_dish(source: str | Path, *, sphere_radius: float | None = None,
              focal_length: float | None = None, resolution: float | None = None,
              mesh_unit: float | None = None) -> Dish:
    """The dish of a scene file (or a shipped example's name) or of a mesh file.

    A mesh is fitted to the paraboloid z = r^2 / (4F) (``focal_length`` fixes F) and refused
    when it is not a dish: F / D outside 0.1 .. 5, or an RMS departure from the fit over 2 %
    of the dish's depth. ``sphere_radius`` (m) sets its probe sphere (default 0.3 F);
    ``mesh_unit`` (m per file unit, default 1) scales its coordinates; ``resolution`` (m) the
    triangle edge of a generated GO mesh, or a mesh file's GO ray spacing.
    """
    if is_mesh(source):
        return _ray_spacing(_mesh_dish(Path(source), sphere_radius, focal_length, unit=mesh_unit),
                            resolution)
    if sphere_radius is not None or focal_length is not None or mesh_unit is not None:
        raise CheckError("--sphere-radius, --focal-length and --mesh-unit apply to a mesh file; a "
                         "scene sets its own in [sphere] and [dish]")
    from raysim.files import find_input

    scene = load_scene(find_input(source))
    if scene.dish.mesh is not None:
        # the dish comes from the scene (its frequency, sphere and deformation), on its mesh
        return _ray_spacing(_mesh_dish(scene.dish.mesh, scene.sphere.radius, scene.dish.focal_length,
                                       scene=scene, source=source), resolution)
    if resolution is not None:
        if not (math.isfinite(resolution) and 0 < resolution <= scene.D / 8):
            raise CheckError(f"--resolution must lie in (0, D/8 = {scene.D / 8:g}] m, got {resolution:g}")
        scene = replace(scene, dish=replace(scene.dish, resolution=float(resolution)))
    face = max(scene.dish.resolution, min(WAVE_FACE_M, scene.D / 25))
    wave = replace(scene, dish=replace(scene.dish, resolution=face), subdivisions=1)
    return Dish(scene, wave, str(source), False,
                notes=(f"wave engines on {face:g} m quadrature faces of the smooth surface, GO on "
                       f"{scene.dish.resolution:g} m triangles x {scene.subdivisions or 1} rays per edge",))


def _ray_spacing(dish: Dish, resolution: float | None) -> Dish:
    """A mesh file's dish with its GO rays ``resolution`` (m) apart on its faces (the
    automatic lattice of :func:`raysim.simulate.go_subdivisions`, over a scene's stated
    ``[go] subdivisions``); unchanged without one."""
    if resolution is None:
        return dish
    if not (math.isfinite(resolution) and 0 < resolution <= dish.D / 8):
        raise CheckError(f"--resolution must lie in (0, D/8 = {dish.D / 8:g}] m, got {resolution:g}")
    go = replace(dish.go, subdivisions=None, ray_spacing=float(resolution))
    return replace(dish, go=go, notes=(*dish.notes, f"GO rays about {resolution:g} m apart on the "
                                       "mesh's faces (--resolution)"))


def _mesh_dish(path: Path, R: float | None, F: float | None, scene: Scene | None = None,
               source: str | Path | None = None, unit: float | None = None) -> Dish:
    """The dish of the mesh file ``path``: a bare mesh (``unit`` m per file unit, default 1),
    or the mesh a ``scene`` (read from ``source``, the dish's recorded source) names."""
    from raysim.surface.mesh import check_stated_dish, load_reflector

    if not path.is_file():
        raise CheckError(f"{path}: no such mesh file")
    if F is not None and not (math.isfinite(F) and F > 0):
        raise CheckError(f"--focal-length must be a length > 0 m, got {F:g}")
    if unit is not None and not (math.isfinite(unit) and unit > 0):
        raise CheckError(f"--mesh-unit must be metres per file unit > 0 (0.001 for mm), got {unit:g}")
    if scene is not None:
        ideal, loaded, fit = load_reflector(path, scene.dish.mesh_unit, F)
    else:
        unit = 1.0 if unit is None else float(unit)
        ideal, loaded, fit = load_reflector(path, unit, F, unit_setting=MESH_UNIT_OPTION)
    if scene is not None:  # its diameter_m was replaced by the mesh's without a word
        check_stated_dish(path, loaded, fit, scene.dish.diameter, F)
    D = float(ideal.D)
    depth = D**2 / (16.0 * fit.F)
    if not 0.1 <= fit.F / D <= 5.0:
        raise CheckError(f"{path}: not a dish: its best-fit paraboloid has F / D = {fit.F / D:.3g} "
                         "(a reflector has 0.1 to 5)")
    if fit.rms > 0.02 * depth:
        raise CheckError(f"{path}: not a dish: it departs {fit.rms:.3g} m RMS from its best-fit "
                         f"paraboloid ({100 * fit.rms / depth:.2g} % of that paraboloid's depth "
                         f"{depth:.3g} m; a dish departs less than 2 %)")
    _check_axis(path, loaded, fit)
    R = SPHERE_RADIUS_OF_F * fit.F if R is None else float(R)
    if not (math.isfinite(R) and 0 < R < fit.F):
        raise CheckError(f"--sphere-radius must lie in (0, F = {fit.F:.4g}) m, got {R:g}")
    if scene is None:
        # JSON's string escapes are TOML's: a name with a quote or a backslash stays a string
        text = (f'name = {json.dumps(path.stem)}\n[dish]\nmesh = {json.dumps(path.resolve().as_posix())}\n'
                f"mesh_unit_m = {unit!r}\nfocal_length_m = {float(fit.F)!r}\n[source]\nfrequency_hz = 1e9\n"
                f"[sphere]\nradius_m = {float(R)!r}\n")
        scene = parse_scene(text, source=str(path), base=path.parent)
    scene = replace(scene, dish=replace(scene.dish, diameter=D, focal_length=fit.F))
    note = (f"mesh {path.name}: {len(ideal.faces):,} faces, {int(ideal.n_panels)} pieces, best-fit "
            f"paraboloid F = {fit.F:.4g} m, D = {D:.4g} m, fit RMS {fit.rms * 1e6:.3g} um; every "
            "engine on that paraboloid plus the file's departure from it, piece by piece")
    return Dish(scene, scene, str(path if source is None else source), True, fit.rms, (note,),
                _size_warning(D, scene=source is not None), int(ideal.n_panels))


#: a mesh whose paraboloid about a tilted axis fits this much better than about z, with the axis
#: more than MIN_TILT_DEG off, is a dish exported out of the reflector frame
TILT_FIT_GAIN = 3.0
MIN_TILT_DEG = 0.2


def _check_axis(path: Path, loaded, fit) -> None:
    """Refuse a mesh whose axis is tilted off +z: a check needs the dish in the reflector frame
    (the sphere about the focus, the wave along the axis). A 12 m dish tilted 5 deg ran for
    34 s and was refused as a scan that 'misses a whole region ... measure it'."""
    from raysim.surface.mesh import axis_tilt

    if fit.rms <= 0:
        return
    tilt, rms = axis_tilt(loaded.vertices)
    if math.degrees(tilt) > MIN_TILT_DEG and TILT_FIT_GAIN * rms < fit.rms:
        raise CheckError(f"{path}: its axis is tilted {math.degrees(tilt):.2f} deg from +z (a "
                         f"paraboloid about the tilted axis fits it to {rms * 1e6:.3g} um RMS, one "
                         f"about z to {fit.rms * 1e6:.3g} um): rotate the mesh into the reflector "
                         "frame, its axis along +z, the wave's direction")


def _size_warning(D: float, scene: bool) -> str:
    """:func:`raysim.simulate.mesh_size_warning` (the same line as ``simulate``'s), with the fix
    ``check`` offers: a scene's ``mesh_unit_m``; "" below the size."""
    from raysim.simulate import mesh_size_warning
    from raysim.surface.mesh import setting_line

    size = mesh_size_warning(D, setting_line("dish.mesh_unit_m" if scene else MESH_UNIT_OPTION, 0.001))
    return f"WARNING: {size}" if size else ""


def frequencies_of(dish: Dish, frequencies: list[float] | tuple[float, ...] | None) -> tuple[float, ...]:
    """The frequencies (Hz) to check: those given, else the scene's; each checked."""
    freqs = tuple(float(f) for f in (frequencies or ()))
    if not freqs:
        if is_mesh(dish.source):
            raise CheckError("a mesh file carries no frequency: give --frequency HZ (one or more)")
        freqs = (dish.go.source.frequency_hz,)
    if len(freqs) > MAX_FREQUENCIES:
        raise CheckError(f"at most {MAX_FREQUENCIES} frequencies, got {len(freqs)}")
    for f in freqs:
        check_frequency(f, "--frequency")
    return tuple(sorted(set(freqs)))


def with_grid(dish: Dish, grid: tuple[int, int] | None) -> Dish:
    """The dish with its probe sphere's cells set to ``grid`` (n_theta, n_phi)."""
    if grid is None:
        return dish
    n_theta, n_phi = grid
    check_sphere_cells(n_theta, n_phi, ("--sphere n_theta", "--sphere n_phi"))
    return replace(dish, go=dish.go.with_overrides(None, n_theta, n_phi),
                   wave=dish.wave.with_overrides(None, n_theta, n_phi))


def parse_grid(text: str | None) -> tuple[int, int] | None:
    """``"90x360"`` -> (90, 360); None stays None."""
    if text is None:
        return None
    try:
        n_theta, n_phi = (int(n) for n in text.lower().split("x"))
    except ValueError:
        raise CheckError(f"--sphere takes the sphere's cells as NTHETAxNPHI (90x360), got {text!r}") from None
    return n_theta, n_phi


# --- the deformation ------------------------------------------------------------------------
def realistic_mix(D: float, rms: float = DEFAULT_RMS_M, seed: int = 0) -> Deformation:
    """Gravity-like rim astigmatism plus actuator-scale bumps, together ``rms`` (m) over the
    aperture: the dataset specs' ``gravity`` and ``bumps`` models (raysim.dataset.models)
    drawn from ``seed``, half the variance each, then scaled together to ``rms``.

    The astigmatism grows as (r/a)^p, p uniform in 2.5..4 (p = 2 would be harmonic: no
    signal); 4 bumps of width D/110 x (1.5 .. 4) m, the paper dish's actuator scale.
    """
    from raysim.dataset.distributions import Distribution
    from raysim.dataset.models import GravityAstigmatism, RandomBumps

    grid = ApertureGrid(D, 128)

    def draw(scale: float) -> Deformation:
        rng = np.random.default_rng(seed)
        part = Distribution("fixed", scale * rms / math.sqrt(2.0))
        gravity = GravityAstigmatism("gravity", part, 1.0, Distribution("uniform", 2.5, 4.0),
                                     Distribution("uniform", 0.0, math.pi))
        bumps = RandomBumps("bumps", part, 1.0, Distribution("fixed", 4.0),
                            Distribution("uniform", 1.5 * D / 110.0, 4.0 * D / 110.0), 0.8)
        parts = [m.draw(rng, grid)[0] for m in (gravity, bumps)]
        return Sum(tuple(p for p in parts if p is not None))

    first = draw(1.0)
    return draw(rms / grid.rms(first))


def choose_deformation(dish: Dish, kind: str, rms: float, seed: int) -> tuple[Dish, Deformation, str]:
    """The dish with the deformation to test with: ``scene`` (the scene's own), ``mix``
    (:func:`realistic_mix`), ``auto`` (the scene's when it has one, else the mix). Returns
    (dish, deformation, description)."""
    if kind not in DEFORMATIONS:
        raise CheckError(f"unknown --deformation {kind!r}: use one of {', '.join(DEFORMATIONS)}")
    if not (math.isfinite(rms) and 0 < rms <= 0.01):
        raise CheckError(f"--rms-um must lie in (0, 10000] um, got {rms * 1e6:g}")
    own = dish.go.deformation
    if kind == "scene" or (kind == "auto" and not isinstance(own, NoDeformation)):
        if isinstance(own, NoDeformation):
            raise CheckError("--deformation scene: the scene has no [[deformation]]; use mix")
        return dish, own, own.describe()
    mix = realistic_mix(dish.D, rms, seed)
    text = f"realistic mix (gravity-like astigmatism + actuator bumps, seed {seed}), {rms * 1e6:g} um RMS"
    return (replace(dish, go=_plain(replace(dish.go, deformation=mix)),
                    wave=_plain(replace(dish.wave, deformation=mix))), mix, text)


def _plain(scene: Scene) -> Scene:
    """A changed scene no longer matches its TOML text: drop the text (the check records it)."""
    return replace(scene, text="")


# --- panels and gaps ------------------------------------------------------------------------
def default_layout(D: float, gap: float) -> PanelLayout:
    """Eight rings of equal width, 6, 12, ..., 48 panels (the paper dish's layout, scaled)."""
    edges = tuple(float(v) for v in np.linspace(0.0, D / 2, 9))
    return PanelLayout(edges, tuple(6 * (i + 1) for i in range(8)), gap)


def check_gap(layout: PanelLayout, gap: float) -> None:
    """Refuse a gap as wide as a panel: at least 4 gaps across each ring and along each panel's
    arc at the ring's mid radius."""
    if not (math.isfinite(gap) and gap >= 0):
        raise CheckError(f"--gap-m must be a width >= 0 m, got {gap:g}")
    for ring in range(layout.n_rings):
        lo, hi = layout.ring_edges[ring], layout.ring_edges[ring + 1]
        arc = math.pi * (lo + hi) / layout.panels_per_ring[ring]
        narrowest = min(hi - lo, arc if layout.panels_per_ring[ring] > 1 else hi - lo)
        if gap > 0.25 * narrowest:
            raise CheckError(f"--gap-m {gap:g} m is wider than a panel allows: ring {ring} panels "
                             f"are {narrowest:.3g} m across (a gap may be at most a quarter of that)")


def with_gap(dish: Dish, gap: float | None) -> Dish:
    """The dish with panel gaps ``gap`` (m): the scene's layout, or :func:`default_layout`."""
    if gap is None:
        return dish
    if not math.isfinite(gap) or gap < 0:
        raise CheckError(f"--gap-m must be a finite width >= 0 m, got {gap:g}")
    if dish.is_mesh:
        raise CheckError("--gap-m applies to a generated dish: a mesh file's gaps are in the file")
    layout = dish.go.panels or default_layout(dish.D, gap)
    check_gap(layout, gap)
    layout = PanelLayout(layout.ring_edges, layout.panels_per_ring, float(gap), layout.phi0)
    return replace(dish, go=_plain(replace(dish.go, panels=layout)),
                   wave=_plain(replace(dish.wave, panels=layout)))


def gap_width(dish: Dish) -> float:
    """The panel gap (m) of a generated dish; NaN for a mesh (its gaps are what the file has)."""
    if dish.is_mesh:
        return math.nan
    return float(dish.go.panels.gap) if dish.go.panels is not None else 0.0


# --- the wave engine ------------------------------------------------------------------------
def wave_cost(dish: Dish, frequency_hz: float, radiator: str = "fast") -> tuple[float, float]:
    """(cost, direct): PO's sums at ``frequency_hz`` for the ideal and the deformed reflector
    (the ideal's quadrature for both, on the integrand's rate for the sphere's points, as
    ``simulate`` makes it) to the sphere's points, as ``radiator`` runs them and as the direct
    sum would, in direct pair evaluations. Plans only, on a reflector that fits the memory."""
    from raysim.optics.fast.radiator import quadrature_cost
    from raysim.optics.po import DEFAULT_SAMPLES_PER_WAVELENGTH
    from raysim.surface.quadrature import plan, targets_around

    wavelength = 299_792_458.0 / frequency_hz
    points = dish.wave.sphere.points(dish.F).reshape(-1, 3)
    k_hat = np.asarray(dish.wave.source.direction, dtype=np.float64)
    targets = targets_around(points, (0.0, 0.0, dish.F), k_hat / np.linalg.norm(k_hat))
    quad = plan(_wave_ideal(dish), wavelength, DEFAULT_SAMPLES_PER_WAVELENGTH, targets)
    cost, direct = quadrature_cost(quad, points, 2.0 * math.pi / wavelength, (0.0, 0.0, dish.F),
                                   radiator)
    return 2.0 * cost, 2.0 * direct


_IDEAL: dict[tuple, object] = {}


def _wave_ideal(dish: Dish):
    """The ideal reflector of the wave scene, built once per dish (the last one kept)."""
    from raysim.surface.mesh import reflectors_for

    key = (dish.wave.dish, dish.wave.panels)
    if key not in _IDEAL:
        _IDEAL.clear()
        _IDEAL[key] = reflectors_for(replace(dish.wave, deformation=NoDeformation()))[0]
    return _IDEAL[key]


@dataclass(frozen=True)
class Engine:
    """The wave engine of one frequency: ``method``, ``why`` in words, and ``seconds`` its data
    (both reflectors) are expected to take (nan for go+edge, whose seconds are not estimated,
    and on a GPU)."""

    method: str
    why: str
    seconds: float = math.nan


def choose_wave(dish: Dish, frequency_hz: float, wave: str, device: str,
                radiator: str = "fast") -> Engine:
    """The wave engine at ``frequency_hz`` (the rule of this module's docstring; its why gives
    the sums' cost as ``radiator`` runs them and, on the CPU, the time it means); ``wave``
    other than ``auto`` forces that engine."""
    from raysim.optics.runtime import cpu_threads
    from raysim.simulate import max_po_samples, physical_memory, po_samples, wave_bytes

    if wave not in WAVE_CHOICES:
        raise CheckError(f"unknown --wave {wave!r}: use one of {', '.join(WAVE_CHOICES)}")
    if wave == "go+edge":
        return Engine(wave, "forced by --wave")
    samples = po_samples(dish.wave.D, frequency_hz)  # as simulate's memory cap counts them
    fits = samples <= max_po_samples()
    if wave != "auto":  # PO or PO + PTD that does not fit is refused by simulate's own check
        cost = wave_cost(dish, frequency_hz, radiator)[0] if fits else math.nan
        return Engine(wave, "forced by --wave", expected_seconds(cost, device))
    memory = (f"{samples:.2g} samples per reflector as simulate's memory cap counts them, about "
              f"{wave_bytes(samples) / 1e9:.2g} GB of this machine's {physical_memory() / 1e9:.3g} GB")
    if not fits:
        return Engine("go+edge", f"PO + PTD would not fit the memory ({memory}): go+edge, whose cost "
                                 "does not grow as f^2")
    cost, direct = wave_cost(dish, frequency_hz, radiator)
    seconds = expected_seconds(cost, device)
    how = "direct sum" if radiator == "direct" else f"{radiator} radiator; direct {direct:.2g}"
    took = "" if math.isnan(seconds) else f", about {duration(seconds)} on {cpu_threads()} CPU threads"
    return Engine("po+ptd", f"PO + PTD fits the memory ({memory}); "
                            f"its sums {cost:.2g} pair evaluations ({how}){took}", seconds)


def expected_seconds(pairs: float, device: str) -> float:
    """Seconds ``pairs`` pair evaluations take on ``device`` (:data:`PAIRS_PER_SECOND_PER_THREAD`
    on each CPU thread); nan on a GPU, whose rate no one has measured yet."""
    from raysim.optics.runtime import cpu_threads

    if str(device).startswith("cuda"):
        return math.nan
    return pairs / (PAIRS_PER_SECOND_PER_THREAD * cpu_threads())


def duration(seconds: float) -> str:
    """``seconds`` in words a user reads at a glance: 40 s, 9 min, 1.5 h."""
    if seconds < 90:
        return f"{max(seconds, 1):.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"
