"""The ``[[deformation]]`` tables of a scene -> :class:`~raysim.surface.deformation.Deformation` objects.

Units at this edge: micrometres (``*_um``), microradians (``*_urad``) and metres (``*_m``);
everything returned is in metres and radians. Several tables add.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from raysim.errors import SceneError
from raysim.surface.deformation import (
    Deformation,
    GaussianBumps,
    NoDeformation,
    PanelRigid,
    PaperDeformation,
    Sum,
    Zernike,
    paper_peak_to_peak,
)
from raysim.surface.mapfile import read_csv_columns, read_map
from raysim.surface.panels import PanelLayout
from raysim.tomlschema import Table

DEFORMATION_KEYS: dict[str, tuple[str, ...]] = {
    "none": (),
    "paper": ("scale", "peak_to_peak_um"),
    "zernike": ("terms", "radius_m"),
    "bumps": ("bumps",),
    "panel_rigid": ("rms_um", "seed", "table"),
    "map": ("file", "scale"),
}
DEFORMATION_TYPES = tuple(DEFORMATION_KEYS)
BUMP_KEYS = ("x_m", "y_m", "amplitude_um", "sigma_m")
MAX_DEFORMATION_M = 0.1  # 10 cm: far beyond any reflector's surface error; a unit mistake


def deformation_of(tables: list[Table], D: float | None, F: float | None,
                   panels: PanelLayout | None, base: Path) -> Deformation:
    """The sum of the ``[[deformation]]`` tables of a dish of diameter ``D`` and focal length
    ``F`` (m; None for a mesh whose dish is fitted later), relative files resolved against
    ``base``."""
    parts: list[Deformation] = []
    for t in tables:
        kind = t.string("type", choices=DEFORMATION_TYPES)
        t.refuse_unknown({"type", *DEFORMATION_KEYS[kind]})
        parts.extend(_one_deformation(t, kind, D, F, panels, base))
        t.done()
    if not parts:
        return NoDeformation()
    return parts[0] if len(parts) == 1 else Sum(tuple(parts))


def _one_deformation(t: Table, kind: str, D, F, panels, base) -> list[Deformation]:
    where = t.where
    if kind == "none":
        return []
    if kind in ("paper", "zernike") and (D is None or F is None):
        raise t.fail(f"'{where}' ({kind}) needs dish.diameter_m and dish.focal_length_m")
    if kind == "paper":
        if t.has("scale") and t.has("peak_to_peak_um"):
            raise t.fail(f"'{where}': give 'scale' or 'peak_to_peak_um', not both")
        ptp_1 = paper_peak_to_peak(D, F)
        if t.has("peak_to_peak_um"):
            scale = t.number("peak_to_peak_um", lo=0.0, hi=MAX_DEFORMATION_M * 1e6,
                             unit="um") * 1e-6 / ptp_1
        else:
            scale = t.number("scale", 1.0)
            if abs(scale) * ptp_1 > MAX_DEFORMATION_M:
                raise t.fail(f"'{where}.scale' = {scale:g} makes a {abs(scale) * ptp_1:.3g} m "
                             f"deformation (over {MAX_DEFORMATION_M * 100:g} cm; scale 1 is "
                             f"{ptp_1 * 1e3:.2f} mm peak to peak)")
        return [PaperDeformation(D, F, scale)]
    if kind == "zernike":
        rows = t.raw("terms", None)
        ok = isinstance(rows, list) and rows and all(
            isinstance(r, list) and len(r) == 3 and all(isinstance(v, int) and not isinstance(v, bool)
                                                         for v in r[:2])
            and isinstance(r[2], int | float) and not isinstance(r[2], bool) for r in rows)
        if not ok:
            raise t.fail(f"'{where}.terms' must be a list of [n, m, coefficient_um] rows")
        for _, _, c in rows:
            if not math.isfinite(c):
                raise t.fail(f"'{where}.terms' coefficient {c} um must be a finite number")
            if abs(c) > MAX_DEFORMATION_M * 1e6:
                raise t.fail(f"'{where}.terms' coefficient {c:g} um is over 10 cm: units are um")
        radius = t.number("radius_m", D / 2, lo=0.0, lo_open=True, unit="m")
        try:
            return [Zernike(tuple((n, m, c * 1e-6) for n, m, c in rows), radius)]
        except SceneError as exc:
            raise t.fail(f"'{where}': {exc}") from exc
    if kind == "bumps":
        bumps = []
        for b in t.tables("bumps", keys=BUMP_KEYS):
            amp = b.number("amplitude_um", unit="um")
            if abs(amp) > MAX_DEFORMATION_M * 1e6:
                raise b.fail(f"'{b.name('amplitude_um')}' = {amp:g} is over 10 cm: units are um")
            bumps.append((b.number("x_m", unit="m"), b.number("y_m", unit="m"), amp * 1e-6,
                          b.number("sigma_m", lo=0.0, lo_open=True, unit="m")))
            b.done()
        if not bumps:
            raise t.fail(f"'{where}' needs at least one entry in 'bumps'")
        return [GaussianBumps(tuple(bumps))]
    if kind == "panel_rigid":
        if panels is None:
            raise t.fail(f"'{where}' (panel_rigid) needs a [panels] layout")
        if t.has("table"):
            if t.has("rms_um") or t.has("seed"):
                raise t.fail(f"'{where}': give 'table' or 'rms_um' (and 'seed'), not both")
            return [_panel_table(t, t.file("table", base), panels)]
        rms = t.number("rms_um", lo=0.0, hi=MAX_DEFORMATION_M * 1e6, unit="um") * 1e-6
        seed = t.integer("seed", 0, lo=0)
        return [PanelRigid.random(panels, rms, seed)]
    if kind == "map":
        if not t.has("file"):
            raise t.fail(f"'{where}' (map) needs 'file' (NetCDF or CSV x,y,dz in m)")
        path = t.file("file", base)
        scale = t.number("scale", 1.0, lo=0.0, lo_open=True)
        try:
            return [read_map(path, scale, limit_m=MAX_DEFORMATION_M)]
        except SceneError as exc:
            raise t.fail(f"'{where}.file': {exc}") from exc
    raise AssertionError(kind)  # pragma: no cover - DEFORMATION_TYPES lists every kind


def _panel_table(t: Table, path: Path, panels: PanelLayout) -> PanelRigid:
    """CSV with header panel,piston_um,tilt_x_urad,tilt_y_urad (tilts = d delta/dx, dy)."""
    where = t.where
    columns = ("panel", "piston_um", "tilt_x_urad", "tilt_y_urad")
    try:
        data = read_csv_columns(path, columns)
    except SceneError as exc:
        raise t.fail(f"'{where}.table': {exc}") from exc
    if not all(np.all(np.isfinite(v)) for v in data.values()):
        raise t.fail(f"'{where}.table' {path}: every cell must be a finite number")
    ids = data["panel"]
    if np.any((ids < 0) | (ids >= panels.n_panels)) or np.any(ids % 1):
        raise t.fail(f"'{where}.table' {path}: panel ids must be integers 0..{panels.n_panels - 1}")
    if np.any(np.abs(data["piston_um"]) > MAX_DEFORMATION_M * 1e6):
        raise t.fail(f"'{where}.table' {path}: a piston is over 10 cm: units are um")
    piston = np.zeros(panels.n_panels)
    tx = np.zeros(panels.n_panels)
    ty = np.zeros(panels.n_panels)
    k = ids.astype(np.int64)
    piston[k] = data["piston_um"] * 1e-6
    tx[k] = data["tilt_x_urad"] * 1e-6
    ty[k] = data["tilt_y_urad"] * 1e-6
    return PanelRigid(panels, piston, tx, ty)
