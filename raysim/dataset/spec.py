"""Dataset specs: a TOML file -> a validated :class:`DatasetSpec` (SI units inside).

A spec names the base scene (inline ``[scene]`` table with the keys of ``scenes/*.toml``, or
``scene = "file.toml"`` beside the spec), how many samples to make and the seed they derive
from, the engine (``method``) and frequencies, the train/validation split, the aperture map
stored per sample, and a list of ``[[errors]]``: random surface errors added to the scene's
own deformation (see :mod:`raysim.dataset.models`), and optionally a ``[measurement]`` table
of measurement effects (see :mod:`raysim.dataset.effects`). Units are in key names (``rms_um``,
``sigma_m``, ``angle_deg``, ``frequencies_hz``) and converted here. Each defect raises
:class:`DatasetError` with one line naming the file and key.

The fingerprint is a SHA-256 of the spec's content (the scene's too), blind to comments and
layout, and of the bytes of every file the scene names (``inputs``: maps, panel tables): a
store records it, and a store made by a different spec, or from another version of one of
those files, is refused on resume.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

from raysim.dataset import toml_text
from raysim.dataset.distributions import Distribution, parse_distribution
from raysim.dataset.effects import Measurement, parse_measurement
from raysim.dataset.models import (
    MODELS,
    ApertureGrid,
    ErrorModel,
    GravityAstigmatism,
    PanelErrors,
    RandomBumps,
    ZernikeSpectrum,
)
from raysim.distributed.inputs import input_digests
from raysim.errors import RaysimError
from raysim.files import find_input
from raysim.methods import METHODS
from raysim.optics.fast.radiator import DEFAULT_TOL, MIN_TOL, RADIATORS
from raysim.scene.scene import Scene, check_frequency, parse_scene
from raysim.simulate import Options, check_method
from raysim.tomlschema import Table, parse_toml, read_text

DTYPES = ("float64", "float32")
TOP_KEYS = ("name", "description", "samples", "seed", "method", "radiator", "radiator_tol", "frequencies_hz",
            "validation_fraction", "grid_n", "dtype", "scene", "errors", "measurement")
_COMMON = ("type", "name", "rms_um", "probability")
_ERROR_KEYS = {
    "zernike": (*_COMMON, "n_min", "n_max", "decay"),
    "bumps": (*_COMMON, "count", "sigma_m", "radius_fraction"),
    "panel_rigid": _COMMON,
    "gravity": (*_COMMON, "exponent", "angle_deg"),
}
_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


class DatasetError(RaysimError, ValueError):
    """A dataset spec or store is unusable (bad key, different spec, not a raysim store)."""


@dataclass(frozen=True)
class DatasetSpec:
    """A validated spec. Frequencies in Hz; ``models`` in spec order; ``text`` as written."""

    name: str
    description: str
    samples: int
    seed: int
    method: str
    frequencies: tuple[float, ...]
    validation_fraction: float
    grid_n: int
    dtype: str
    scene: Scene
    scene_text: str
    models: tuple[ErrorModel, ...]
    text: str
    source: str
    base: Path
    fingerprint: str
    measurement: Measurement | None = None  # the [measurement] effects (raysim.dataset.effects)
    radiator: str = "fast"  # po, po+ptd: the sum of the elements' fields (fast or direct)
    radiator_tol: float = 1e-6  # the fast sum's relative accuracy
    # (file the scene names, relative to base; its SHA-256), sorted: a tuple keeps the spec hashable
    inputs: tuple[tuple[str, str], ...] = ()

    @cached_property
    def grid(self) -> ApertureGrid:
        """The aperture grid of the stored deformation maps."""
        return ApertureGrid(self.scene.D, self.grid_n, self.scene.panels)

    @property
    def n_validation(self) -> int:
        """Samples in the validation split: round(fraction * samples)."""
        return round(self.validation_fraction * self.samples)


def load_spec(path: str | Path) -> DatasetSpec:
    """Read and validate a spec TOML file (a scene file it names resolves beside it). A name
    that is not an existing path may name a shipped example (``dataset_demo``)."""
    path = find_input(path)
    text = read_text(path, "dataset spec", DatasetError)
    return parse_spec(text, source=str(path), base=path.parent)


def parse_spec(text: str, source: str = "spec", base: Path | None = None) -> DatasetSpec:
    """Validate spec TOML ``text``; ``source`` names it in messages, ``base`` resolves files."""
    base = (base or Path.cwd()).resolve()
    raw = parse_toml(text, source, DatasetError)
    top = Table(raw, source=source, error=DatasetError, keys=TOP_KEYS)
    try:
        return _build(top, text, source, base)
    except ValueError as exc:  # messages of parse_distribution
        if isinstance(exc, RaysimError):
            raise
        raise DatasetError(f"{source}: {exc}") from exc


def _build(top: Table, text: str, source: str, base: Path) -> DatasetSpec:
    if not top.has("scene"):
        raise top.fail("missing 'scene' (an inline [scene] table or a scene file name)")
    scene_text, scene_table = _scene_source(top, base)
    scene = parse_scene(scene_text, source=f"{source} [scene]", base=base)
    if scene.dish.mesh is not None:
        raise top.fail("the dataset's scene must be a generated paraboloid (no dish.mesh): the "
                       "stored deformation maps could not include the mesh's own errors")
    if scene.obstacles:
        raise top.fail("the dataset's scene has [[obstacle]] tables: datasets store no blocked "
                       "mask yet, so their samples would hold shadows nobody marks")
    name = top.string("name", None) or (Path(source).stem if source != "spec" else "dataset")
    description = top.string("description", "")
    samples = top.integer("samples", lo=1, hi=10_000_000)
    seed = top.integer("seed", lo=0, hi=2**63 - 1)
    method = top.string("method", "go", choices=METHODS)
    radiator = top.string("radiator", "fast", choices=RADIATORS)
    radiator_tol = top.number("radiator_tol", DEFAULT_TOL, lo=MIN_TOL, hi=1.0, hi_open=True)
    freqs = top.raw("frequencies_hz", [scene.source.frequency_hz])
    if not isinstance(freqs, list) or not freqs or not all(
            isinstance(f, int | float) and not isinstance(f, bool) and math.isfinite(f) and f >= 1e6
            for f in freqs):
        raise top.fail(f"'frequencies_hz' must be a non-empty list of frequencies >= 1e6 Hz "
                       f"(in Hz, not GHz), got {freqs!r}")
    for f in freqs:
        try:
            check_frequency(float(f), "'frequencies_hz'")
            # the engine's own limits (PO's source samples per reflector), as simulate has them
            check_method(scene.with_overrides(frequency_hz=float(f)), method, Options())
        except RaysimError as exc:
            raise top.fail(str(exc)) from exc
    if len(set(freqs)) != len(freqs):
        raise top.fail("'frequencies_hz' lists a frequency twice")
    fraction = top.number("validation_fraction", 0.2, lo=0.0, hi=1.0)
    dtype = top.string("dtype", "float64", choices=DTYPES)
    grid_n = top.integer("grid_n", 128, lo=8, hi=4096)
    models = _models(top.tables("errors"), scene)
    effects = top.raw("measurement", None)
    measurement = parse_measurement(effects) if effects is not None else None
    top.done()
    inputs = input_digests(scene.files, base)
    fingerprint = _fingerprint(top.data, scene_table, inputs)
    return DatasetSpec(
        name=str(name), description=str(description), samples=samples, seed=seed,
        method=method, frequencies=tuple(float(f) for f in freqs), validation_fraction=fraction,
        grid_n=grid_n, dtype=dtype, scene=scene, scene_text=scene_text,
        models=models, text=text, source=source, base=base, fingerprint=fingerprint,
        measurement=measurement, radiator=radiator, radiator_tol=radiator_tol,
        inputs=tuple(inputs.items()))


def _fingerprint(data: dict, scene_table: dict, inputs: dict[str, str]) -> str:
    """SHA-256 of the spec's content, its scene's and the digests of the files the scene names
    (left out when it names none: such a spec's fingerprint is the one it always had)."""
    canonical = {**data, "scene": scene_table}
    if inputs:
        canonical["inputs"] = inputs
    return hashlib.sha256(json.dumps(canonical, sort_keys=True).encode()).hexdigest()


def _scene_source(top: Table, base: Path) -> tuple[str, dict]:
    """(scene TOML text, its table) from a file name beside the spec or an inline table."""
    value = top.raw("scene")
    if isinstance(value, dict):
        return toml_text.dumps(value), value
    if not isinstance(value, str):
        raise top.fail(f"'scene' must be a scene file name or a [scene] table, got {value!r}")
    path = find_input(value, base)
    if not path.is_file():
        raise top.fail(f"'scene': no such scene file {path}")
    text = read_text(path, "scene", DatasetError)
    return text, parse_toml(text, str(path), DatasetError)


def _models(tables: list[Table], scene: Scene) -> tuple[ErrorModel, ...]:
    kinds = [t.raw("type", None) for t in tables]
    models: list[ErrorModel] = []
    for i, t in enumerate(tables):
        where = t.where
        kind = t.string("type", choices=tuple(MODELS))
        t.refuse_unknown(set(_ERROR_KEYS[kind]))
        name = t.raw("name", kind if kinds.count(kind) == 1 else f"{kind}{kinds[:i].count(kind)}")
        if not isinstance(name, str) or not _NAME.match(name):
            raise t.fail(f"'{where}.name' must be lower-case letters, digits and _, got {name!r}")
        if name in [m.name for m in models]:
            raise t.fail(f"'{where}.name' {name!r} is used twice")
        if not t.has("rms_um"):
            raise t.fail(f"'{where}' needs 'rms_um' (a number or a law, micrometres)")
        rms = _scaled(parse_distribution(t.raw("rms_um"), f"{where}.rms_um", lo=0.0, hi=1e5), 1e-6)
        probability = t.number("probability", 1.0, lo=0.0, hi=1.0)
        common = {"name": name, "rms": rms, "probability": probability}
        models.append(_model(kind, t, where, common, scene))
        t.done()
    return tuple(models)


def _model(kind: str, t: Table, where: str, common: dict, scene: Scene) -> ErrorModel:
    if kind == "zernike":
        n_min = t.integer("n_min", 2, lo=0, hi=20)
        n_max = t.integer("n_max", max(6, n_min), lo=n_min, hi=20)
        return ZernikeSpectrum(**common, n_min=n_min, n_max=n_max,
                               decay=t.number("decay", 1.0, lo=0.0, hi=10.0))
    if kind == "bumps":
        count = parse_distribution(t.raw("count", 4), f"{where}.count", lo=1, hi=1000, integer=True)
        sigma = parse_distribution(t.raw("sigma_m", 2.0), f"{where}.sigma_m", lo=0.0, hi=scene.D)
        if sigma.support[0] <= 0:
            raise t.fail(f"'{where}.sigma_m' must stay > 0 m")
        fraction = t.number("radius_fraction", 1.0, lo=0.0, hi=1.5)
        return RandomBumps(**common, count=count, sigma=sigma, fraction=fraction)
    if kind == "panel_rigid":
        if scene.panels is None:
            raise t.fail(f"'{where}' (panel_rigid) needs a [scene.panels] layout")
        return PanelErrors(**common)
    exponent = parse_distribution(t.raw("exponent", 3.0), f"{where}.exponent", lo=2.0, hi=12.0)
    angle = _scaled(parse_distribution(t.raw("angle_deg", 0.0), f"{where}.angle_deg"),
                    math.pi / 180.0)
    return GravityAstigmatism(**common, exponent=exponent, angle=angle)


def _scaled(dist: Distribution, factor: float) -> Distribution:
    """The law of factor * X (unit conversion at the edge)."""
    return Distribution(dist.law, dist.a * factor, dist.b * factor)
