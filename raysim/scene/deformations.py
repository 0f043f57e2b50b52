"""The ``[[deformation]]`` tables of a scene -> :class:`~raysim.surface.deformation.Deformation` objects.

Units at this edge: micrometres (``*_um``), microradians (``*_urad``) and metres (``*_m``);
everything returned is in metres and radians. Several tables add.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from raysim.errors import SceneError
from raysim.scene.schema import INT, LIST, NUM, STR, TABLES, KeyChecker, resolve
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
from raysim.surface.gridded import GriddedMap
from raysim.surface.panels import PanelLayout

DEFORMATION_KEYS: dict[str, dict[str, str]] = {
    "none": {},
    "paper": {"scale": NUM, "peak_to_peak_um": NUM},
    "zernike": {"terms": LIST, "radius_m": NUM},
    "bumps": {"bumps": TABLES},
    "panel_rigid": {"rms_um": NUM, "seed": INT, "table": STR},
    "map": {"file": STR, "scale": NUM},
}
BUMP_KEYS = {"x_m": NUM, "y_m": NUM, "amplitude_um": NUM, "sigma_m": NUM}


def deformation_of(ctx: KeyChecker, entries: list, D: float | None, F: float | None,
                   panels: PanelLayout | None, base: Path) -> Deformation:
    """The sum of the ``[[deformation]]`` tables ``entries`` of a dish of diameter ``D`` and
    focal length ``F`` (m; None for a mesh whose dish is fitted later), relative files
    resolved against ``base``."""
    parts: list[Deformation] = []
    for i, entry in enumerate(entries):
        where = f"deformation[{i}]"
        kind = entry.get("type")
        if kind not in DEFORMATION_KEYS:
            raise ctx.fail("", f"'{where}.type' must be one of {', '.join(DEFORMATION_KEYS)}, got {kind!r}")
        body = {k: v for k, v in entry.items() if k != "type"}
        ctx.check_keys(body, where, DEFORMATION_KEYS[kind])
        parts.extend(_one_deformation(ctx, where, kind, body, D, F, panels, base))
    if not parts:
        return NoDeformation()
    return parts[0] if len(parts) == 1 else Sum(tuple(parts))


def _one_deformation(ctx, where, kind, body, D, F, panels, base) -> list[Deformation]:
    if kind == "none":
        return []
    if kind in ("paper", "zernike") and (D is None or F is None):
        raise ctx.fail("", f"'{where}' ({kind}) needs dish.diameter_m and dish.focal_length_m")
    if kind == "paper":
        if "scale" in body and "peak_to_peak_um" in body:
            raise ctx.fail("", f"'{where}': give 'scale' or 'peak_to_peak_um', not both")
        scale = ctx.number(body, where, "scale", 1.0)
        if "peak_to_peak_um" in body:
            ptp = ctx.number(body, where, "peak_to_peak_um", lo=0.0) * 1e-6
            scale = ptp / paper_peak_to_peak(D, F)
        return [PaperDeformation(D, F, scale)]
    if kind == "zernike":
        rows = body.get("terms", [])
        ok = all(isinstance(r, list) and len(r) == 3 and isinstance(r[0], int) and isinstance(r[1], int)
                 and isinstance(r[2], int | float) for r in rows)
        if not rows or not ok:
            raise ctx.fail("", f"'{where}.terms' must be a list of [n, m, coefficient_um] rows")
        for _, _, c in rows:
            if abs(c) > 1e5:
                raise ctx.fail("", f"'{where}.terms' coefficient {c:g} um is over 10 cm: units are um")
        radius = ctx.number(body, where, "radius_m", D / 2, lo=0.0, lo_open=True)
        try:
            return [Zernike(tuple((n, m, c * 1e-6) for n, m, c in rows), radius)]
        except SceneError as exc:
            raise ctx.fail("", f"'{where}': {exc}") from exc
    if kind == "bumps":
        bumps = []
        for j, b in enumerate(body.get("bumps", [])):
            name = f"{where}.bumps[{j}]"
            ctx.check_keys(b, name, BUMP_KEYS)
            amp = ctx.number(b, name, "amplitude_um")
            if abs(amp) > 1e5:
                raise ctx.fail("", f"'{name}.amplitude_um' = {amp:g} is over 10 cm: units are um")
            bumps.append((ctx.number(b, name, "x_m"), ctx.number(b, name, "y_m"), amp * 1e-6,
                          ctx.number(b, name, "sigma_m", lo=0.0, lo_open=True)))
        if not bumps:
            raise ctx.fail("", f"'{where}' needs at least one entry in 'bumps'")
        return [GaussianBumps(tuple(bumps))]
    if kind == "panel_rigid":
        if panels is None:
            raise ctx.fail("", f"'{where}' (panel_rigid) needs a [panels] layout")
        if "table" in body:
            return [_panel_table(ctx, where, resolve(ctx, base, body["table"], f"{where}.table"), panels)]
        rms = ctx.number(body, where, "rms_um", lo=0.0) * 1e-6
        if rms > 0.1:
            raise ctx.fail("", f"'{where}.rms_um' is over 10 cm: units are um")
        seed = ctx.integer(body, where, "seed", 0, lo=0)
        return [PanelRigid.random(panels, rms, seed)]
    if kind == "map":
        if "file" not in body:
            raise ctx.fail("", f"'{where}' (map) needs 'file' (NetCDF or CSV x,y,dz in m)")
        path = resolve(ctx, base, body["file"], f"{where}.file")
        try:
            return [GriddedMap.from_file(path, ctx.number(body, where, "scale", 1.0))]
        except SceneError as exc:
            raise ctx.fail("", f"'{where}': {exc}") from exc
    raise AssertionError(kind)  # pragma: no cover - the schema lists every kind


def _panel_table(ctx: KeyChecker, where: str, path: Path, panels: PanelLayout) -> PanelRigid:
    """CSV with header panel,piston_um,tilt_x_urad,tilt_y_urad (tilts = d delta/dx, dy)."""
    try:
        data = np.genfromtxt(path, delimiter=",", names=True, dtype=np.float64)
    except ValueError as exc:
        raise ctx.fail("", f"'{where}.table' {path}: bad CSV ({exc})") from exc
    need = {"panel", "piston_um", "tilt_x_urad", "tilt_y_urad"}
    if data.dtype.names is None or not need <= set(data.dtype.names):
        raise ctx.fail("", f"'{where}.table' {path}: header must be panel,piston_um,tilt_x_urad,tilt_y_urad")
    data = np.atleast_1d(data)
    ids = data["panel"]
    if not np.all(np.isfinite(ids)) or np.any((ids < 0) | (ids >= panels.n_panels)) or np.any(ids % 1):
        raise ctx.fail("", f"'{where}.table' {path}: panel ids must be integers 0..{panels.n_panels - 1}")
    piston = np.zeros(panels.n_panels)
    tx = np.zeros(panels.n_panels)
    ty = np.zeros(panels.n_panels)
    k = ids.astype(np.int64)
    piston[k] = data["piston_um"] * 1e-6
    tx[k] = data["tilt_x_urad"] * 1e-6
    ty[k] = data["tilt_y_urad"] * 1e-6
    if not (np.all(np.isfinite(piston)) and np.all(np.isfinite(tx)) and np.all(np.isfinite(ty))):
        raise ctx.fail("", f"'{where}.table' {path}: every row needs numbers")
    return PanelRigid(panels, piston, tx, ty)
