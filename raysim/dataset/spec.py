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
layout: a store records it, and a store made by a different spec is refused on resume.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
import re
import tomllib
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

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
from raysim.errors import RaysimError
from raysim.scene.scene import Scene, parse_scene
from raysim.simulate import METHODS

DTYPES = ("float64", "float32")
_TOP = {"name": str, "description": str, "samples": int, "seed": int, "method": str,
        "frequencies_hz": list, "validation_fraction": float, "grid_n": int, "dtype": str,
        "scene": (str, dict), "errors": list, "measurement": dict}
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

    @cached_property
    def grid(self) -> ApertureGrid:
        """The aperture grid of the stored deformation maps."""
        return ApertureGrid(self.scene.D, self.grid_n, self.scene.panels)

    @property
    def n_validation(self) -> int:
        """Samples in the validation split: round(fraction * samples)."""
        return round(self.validation_fraction * self.samples)


def load_spec(path: str | Path) -> DatasetSpec:
    """Read and validate a spec TOML file (a scene file it names resolves beside it)."""
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: no such dataset spec")
    return parse_spec(path.read_text(encoding="utf-8"), source=str(path), base=path.parent)


def parse_spec(text: str, source: str = "spec", base: Path | None = None) -> DatasetSpec:
    """Validate spec TOML ``text``; ``source`` names it in messages, ``base`` resolves files."""
    base = (base or Path.cwd()).resolve()
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise DatasetError(f"{source}: not valid TOML ({exc})") from exc
    try:
        return _build(raw, text, source, base)
    except ValueError as exc:  # messages from the checks below and from parse_distribution
        if isinstance(exc, RaysimError):
            raise
        raise DatasetError(f"{source}: {exc}") from exc


def _build(raw: dict, text: str, source: str, base: Path) -> DatasetSpec:
    _check_keys(raw, _TOP, "")
    for key, kind in _TOP.items():
        if key in raw and not _is(raw[key], kind):
            raise ValueError(f"'{key}' has the wrong type ({type(raw[key]).__name__}: {raw[key]!r})")
    if "scene" not in raw:
        raise ValueError("missing 'scene' (an inline [scene] table or a scene file name)")
    scene_text, scene_table = _scene_source(raw["scene"], base)
    scene = parse_scene(scene_text, source=f"{source} [scene]", base=base)
    if scene.dish.mesh is not None:
        raise ValueError("the dataset's scene must be a generated paraboloid (no dish.mesh): the "
                         "stored deformation maps could not include the mesh's own errors")
    samples = _int(raw, "samples", None, 1, 10_000_000)
    seed = _int(raw, "seed", None, 0, 2**63 - 1)
    method = raw.get("method", "go")
    if method not in METHODS:
        raise ValueError(f"'method' must be one of {', '.join(METHODS)}, got {method!r}")
    freqs = raw.get("frequencies_hz", [scene.source.frequency_hz])
    if not freqs or not all(_is(f, float) and math.isfinite(f) and f >= 1e6 for f in freqs):
        raise ValueError(f"'frequencies_hz' must be a non-empty list of frequencies >= 1e6 Hz "
                         f"(in Hz, not GHz), got {freqs!r}")
    if len(set(freqs)) != len(freqs):
        raise ValueError("'frequencies_hz' lists a frequency twice")
    fraction = float(raw.get("validation_fraction", 0.2))
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"'validation_fraction' must lie in [0, 1], got {fraction:g}")
    dtype = raw.get("dtype", "float64")
    if dtype not in DTYPES:
        raise ValueError(f"'dtype' must be one of {', '.join(DTYPES)}, got {dtype!r}")
    models = _models(raw.get("errors", []), scene)
    canonical = {**raw, "scene": scene_table}
    fingerprint = hashlib.sha256(json.dumps(canonical, sort_keys=True).encode()).hexdigest()
    name = raw.get("name") or (Path(source).stem if source != "spec" else "dataset")
    return DatasetSpec(
        name=str(name), description=str(raw.get("description", "")), samples=samples, seed=seed,
        method=method, frequencies=tuple(float(f) for f in freqs), validation_fraction=fraction,
        grid_n=_int(raw, "grid_n", 128, 8, 4096), dtype=dtype, scene=scene, scene_text=scene_text,
        models=models, text=text, source=source, base=base, fingerprint=fingerprint,
        measurement=parse_measurement(raw["measurement"]) if "measurement" in raw else None)


def _scene_source(value: str | dict, base: Path) -> tuple[str, dict]:
    """(scene TOML text, its table) from a file name beside the spec or an inline table."""
    if isinstance(value, dict):
        return toml_text.dumps(value), value
    path = Path(value)
    path = path if path.is_absolute() else base / path
    if not path.is_file():
        raise ValueError(f"'scene': no such scene file {path}")
    text = path.read_text(encoding="utf-8")
    try:
        return text, tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"'scene' {path}: not valid TOML ({exc})") from exc


def _models(entries: list, scene: Scene) -> tuple[ErrorModel, ...]:
    if not all(isinstance(e, dict) for e in entries):
        raise ValueError("'errors' must be a list of [[errors]] tables")
    kinds = [e.get("type") for e in entries]
    models: list[ErrorModel] = []
    for i, entry in enumerate(entries):
        where = f"errors[{i}]"
        kind = entry.get("type")
        if kind not in MODELS:
            raise ValueError(f"'{where}.type' must be one of {', '.join(MODELS)}, got {kind!r}")
        _check_keys(entry, dict.fromkeys(_ERROR_KEYS[kind]), where)
        name = entry.get("name", kind if kinds.count(kind) == 1 else f"{kind}{kinds[:i].count(kind)}")
        if not isinstance(name, str) or not _NAME.match(name):
            raise ValueError(f"'{where}.name' must be lower-case letters, digits and _, got {name!r}")
        if name in [m.name for m in models]:
            raise ValueError(f"'{where}.name' {name!r} is used twice")
        if "rms_um" not in entry:
            raise ValueError(f"'{where}' needs 'rms_um' (a number or a law, micrometres)")
        rms = _scaled(parse_distribution(entry["rms_um"], f"{where}.rms_um", lo=0.0, hi=1e5), 1e-6)
        probability = _number(entry, "probability", 1.0, 0.0, 1.0, where)
        common = {"name": name, "rms": rms, "probability": probability}
        models.append(_model(kind, entry, where, common, scene))
    return tuple(models)


def _model(kind: str, entry: dict, where: str, common: dict, scene: Scene) -> ErrorModel:
    if kind == "zernike":
        n_min = _int(entry, "n_min", 2, 0, 20, where)
        n_max = _int(entry, "n_max", max(6, n_min), n_min, 20, where)
        return ZernikeSpectrum(**common, n_min=n_min, n_max=n_max,
                               decay=_number(entry, "decay", 1.0, 0.0, 10.0, where))
    if kind == "bumps":
        count = parse_distribution(entry.get("count", 4), f"{where}.count", lo=1, hi=1000, integer=True)
        sigma = parse_distribution(entry.get("sigma_m", 2.0), f"{where}.sigma_m", lo=0.0, hi=scene.D)
        if sigma.support[0] <= 0:
            raise ValueError(f"'{where}.sigma_m' must stay > 0 m")
        fraction = _number(entry, "radius_fraction", 1.0, 0.0, 1.5, where)
        return RandomBumps(**common, count=count, sigma=sigma, fraction=fraction)
    if kind == "panel_rigid":
        if scene.panels is None:
            raise ValueError(f"'{where}' (panel_rigid) needs a [scene.panels] layout")
        return PanelErrors(**common)
    exponent = parse_distribution(entry.get("exponent", 3.0), f"{where}.exponent", lo=2.0, hi=12.0)
    angle = _scaled(parse_distribution(entry.get("angle_deg", 0.0), f"{where}.angle_deg"),
                    math.pi / 180.0)
    return GravityAstigmatism(**common, exponent=exponent, angle=angle)


def _scaled(dist: Distribution, factor: float) -> Distribution:
    """The law of factor * X (unit conversion at the edge)."""
    return Distribution(dist.law, dist.a * factor, dist.b * factor)


def _check_keys(table: dict, known: dict, where: str) -> None:
    for key in table:
        if key not in known:
            hint = difflib.get_close_matches(key, list(known), n=1)
            extra = f" (did you mean '{hint[0]}'?)" if hint else f" (known: {', '.join(known)})"
            raise ValueError(f"unknown key '{f'{where}.{key}' if where else key}'{extra}")


def _is(value: Any, kind: Any) -> bool:
    if isinstance(value, bool):
        return kind is bool
    if kind is float:
        return isinstance(value, int | float)
    return isinstance(value, kind)


def _int(table: dict, key: str, default: int | None, lo: int, hi: int, where: str = "") -> int:
    name = f"{where}.{key}" if where else key
    if key not in table:
        if default is None:
            raise ValueError(f"missing key '{name}'")
        return default
    value = table[key]
    if not _is(value, int) or not lo <= value <= hi:
        raise ValueError(f"'{name}' must be an integer in {lo}..{hi}, got {value!r}")
    return int(value)


def _number(table: dict, key: str, default: float, lo: float, hi: float, where: str) -> float:
    value = table.get(key, default)
    if not _is(value, float) or not lo <= value <= hi:
        raise ValueError(f"'{where}.{key}' must be a number in [{lo:g}, {hi:g}], got {value!r}")
    return float(value)
