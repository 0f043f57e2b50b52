"""``check.html``: the verdict, the table across frequencies, the band tables, the FA maps, the
surface error maps and the frequency trend of a ``raysim check`` dataset, on one
self-contained page (PNG figures embedded as base64, the same PNGs beside it in ``figures/``),
in the style of ``raysim report`` (:mod:`raysim.pipeline.report`).

Maps: (phi, theta) in degrees on the probe sphere, theta from -z at the focus; the aperture in
m (x, y), deformations in um.
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np
import xarray as xr

from raysim.files import write_bytes, write_text
from raysim.pipeline.check_verdict import summary_rows, verdict_lines
from raysim.pipeline.report import PAGE_STYLE, figure_html, png_bytes
from raysim.render import backend
from raysim.render.charts import RIM_STYLE, cell_edges, colour_map, rim_circle
from raysim.render.data import UM, deformation_limit, symmetric_limit

SIZE = (1800, 620)


def write_page(ds: xr.Dataset, out: Path) -> Path:
    """Draw the figures of ``ds`` into ``out/figures`` and write ``out/check.html``."""
    (out / "figures").mkdir(exist_ok=True)
    blocks = []
    for name, caption, fig in _figures(ds):
        png = png_bytes(backend.figure_image(fig))
        write_bytes(out / "figures" / f"{name}.png", png)
        blocks.append((name, figure_html(name, caption, png)))
    path = out / "check.html"
    write_text(path, _page(ds, dict(blocks)))
    return path


def _figures(ds: xr.Dataset):
    if ds.sizes["frequency"] > 1:
        yield "trend", "How GO's errors change with frequency: FA and ideal-intensity differences, " \
                       "and the surface error the GO assumption costs.", trend_figure(ds)
    for i, f in enumerate(ds["frequency"].values):
        tag = f"{f / 1e9:g}GHz"
        yield f"fa_{tag}", (f"FA = I_ideal / I_def - 1 at {f / 1e9:g} GHz: GO, the wave engine "
                            f"({ds['wave_method'].values[i]}) and their difference; dashed: the rim "
                            "image."), fa_figure(ds, i)
        if "error_go_model" in ds:
            yield f"surface_{tag}", (f"Surface at {f / 1e9:g} GHz: the deformation tested and the error "
                                     "of each inversion (recovered - truth), µm."), surface_figure(ds, i)


def fa_figure(ds: xr.Dataset, i: int):
    """FA of GO, of the wave engine and GO - wave on (phi, theta) maps."""
    phi, theta = np.degrees(ds["phi"].values), np.degrees(ds["theta"].values)
    rim = 2.0 * math.degrees(math.atan(ds.attrs["diameter"] / (4.0 * ds.attrs["focal_length"])))
    fig = backend.figure(SIZE)
    maps = [("GO", ds["fa_go"].values[i]), (str(ds["wave_method"].values[i]), ds["fa_wave"].values[i]),
            ("GO - wave", ds["fa_difference_map"].values[i])]
    shared = symmetric_limit(np.concatenate([maps[0][1].ravel(), maps[1][1].ravel()]))
    for ax, (label, values) in zip(fig.subplots(1, 3), maps, strict=True):
        limit = shared if label != "GO - wave" else symmetric_limit(values)
        limit = limit if math.isfinite(limit) and limit > 0 else 1.0
        image = ax.pcolormesh(cell_edges(phi), cell_edges(theta), np.ma.masked_invalid(values),
                              cmap=colour_map("RdBu_r"), vmin=-limit, vmax=limit, shading="flat",
                              rasterized=True)
        ax.axhline(rim, **RIM_STYLE)
        ax.set_xlabel("phi (deg)")
        ax.set_ylabel("theta (deg)")
        ax.set_title(f"FA, {label}")
        fig.colorbar(image, ax=ax, shrink=0.85)
    return fig


def surface_figure(ds: xr.Dataset, i: int):
    """The truth and the three inversions' errors over the aperture (um)."""
    x, y = ds["x"].values, ds["y"].values
    panels = [("deformation tested", ds["truth"].values if "truth" in ds else None)]
    panels += [(ds[f"error_{n}"].attrs["long_name"].removeprefix("recovered - truth: "),
                ds[f"error_{n}"].values[i]) for n in ("go_data", "go_model", "wave_model")
               if f"error_{n}" in ds]
    panels = [(label, v) for label, v in panels if v is not None]
    fig = backend.figure((450 * len(panels), 520))
    errors = [deformation_limit(v) for _, v in panels[1:]]
    error_limit = max(errors) if errors else 1.0
    for k, (ax, (label, values)) in enumerate(zip(np.atleast_1d(fig.subplots(1, len(panels))), panels,
                                                  strict=True)):
        limit = deformation_limit(values) if k == 0 else error_limit
        image = ax.pcolormesh(cell_edges(x), cell_edges(y), np.ma.masked_invalid(values * UM),
                              cmap="RdBu_r", vmin=-limit, vmax=limit, shading="flat", rasterized=True)
        rim_circle(ax, 0.5 * float(ds.attrs["diameter"]))
        ax.set_aspect("equal")
        ax.set_title(f"{label}\nRMS {np.sqrt(np.nanmean(values ** 2)) * UM:.3g} µm", fontsize=10)
        ax.set_xlabel("x (m)")
        fig.colorbar(image, ax=ax, orientation="horizontal", shrink=0.9, pad=0.1, label="µm")
    return fig


def trend_figure(ds: xr.Dataset):
    """FA and ideal differences (%), and the GO cost (um), against frequency (GHz), log axes."""
    f = ds["frequency"].values / 1e9
    fig = backend.figure((1400, 560))
    left, right = fig.subplots(1, 2)
    left.loglog(f, 100 * ds["fa_difference"].values, "o-", label="FA: RMS(GO - wave) / RMS(wave)")
    left.loglog(f, 100 * ds["ideal_difference"].values, "s-",
                label="ideal intensity: RMS(GO - wave) / RMS(wave)")
    left.axhline(5.0, color="0.5", linestyle=":", label="5 %: GO holds below")
    left.set_xlabel("frequency (GHz)")
    left.set_ylabel("difference (%)")
    left.legend(fontsize=9)
    for name, label in (("cost_go_model", "GO assumption's cost (GO refinement of wave data)"),
                        ("cost_wave_model", "left after the wave-aware refinement")):
        if name in ds and np.isfinite(ds[name].values).any():
            right.semilogx(f, UM * ds[name].values, "o-", label=label)
    right.set_xlabel("frequency (GHz)")
    right.set_ylabel("RMS against GO's own inversion (µm)")
    right.legend(fontsize=9)
    return fig


def _table(rows: list[list[str]]) -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in rows[0])
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows[1:])
    return f"<table><tr>{head}</tr>{body}</table>"


def band_rows(ds: xr.Dataset, i: int) -> list[list[str]]:
    """The band table of frequency ``i``: theta range (deg), FA RMS, FA and ideal differences."""
    rows = [["theta (deg)", "FA RMS (wave)", "FA difference / FA RMS", "ideal intensity difference"]]
    for b in range(ds.sizes["band"]):
        lo, hi = math.degrees(ds["band_lo"].values[b]), math.degrees(ds["band_hi"].values[b])
        rows.append([f"{lo:.0f} - {hi:.0f}",
                     f"{ds['band_fa_rms'].values[i, b]:.3g}",
                     f"{100 * ds['band_fa_difference'].values[i, b]:.1f} %",
                     f"{100 * ds['band_ideal_difference'].values[i, b]:.2f} %"])
    return rows


def _page(ds: xr.Dataset, figures: dict[str, str]) -> str:
    a = ds.attrs
    name = html.escape(Path(str(a["source"])).name)
    verdict = "".join(f"<li>{html.escape(line)}</li>" for line in verdict_lines(ds))
    sections = [figures.get("trend", "")]
    for i, f in enumerate(ds["frequency"].values):
        tag = f"{f / 1e9:g}GHz"
        sections.append(f"<h2>{f / 1e9:g} GHz: {html.escape(str(ds['wave_method'].values[i]))}</h2>"
                        f"<p>{html.escape(str(ds['wave_reason'].values[i]))}</p>"
                        f"{_table(band_rows(ds, i))}{figures.get(f'fa_{tag}', '')}"
                        f"{figures.get(f'surface_{tag}', '')}")
    scene = f"<h2>Scene</h2><pre>{html.escape(str(a['scene']))}</pre>" if a.get("scene") else ""
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>raysim check: {name}</title>
{PAGE_STYLE}</head><body>
<h1>raysim check: {name}</h1>
<p>Does the deformation-intensity equation's GO assumption hold for this dish? GO against a wave
engine with the same deformation ({html.escape(str(a['deformation']))}); D = {a['diameter']:.4g} m,
F = {a['focal_length']:.4g} m, probe sphere R = {a['sphere_radius']:.4g} m,
{ds.sizes['theta']} x {ds.sizes['phi']} cells. {html.escape(str(a['dish_notes']))}.</p>
<h2>Verdict</h2><ul>{verdict}</ul>
{_table(summary_rows(ds))}
<p>GO holds where FA differs from the wave engine's by at most 5 % of FA's RMS (marginal: 20 %).
The GO cost is the RMS difference between the wave data inverted with GO and GO's own data
inverted the same way: what the missing physics costs, apart from what no scan can see (the
harmonic part without rim targets). Engine rule: {html.escape(str(a['rule']))}</p>
{"".join(sections)}
{scene}
<p>raysim {html.escape(str(a.get('raysim_version', '')))}; every number and map is in check.nc beside
this page.</p>
</body></html>
"""
