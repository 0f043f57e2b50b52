"""The verdict of a check in words and numbers, read from its dataset alone
(:func:`raysim.pipeline.check.check`): one sentence per frequency and the table across them.

FA differences are fractions of FA's RMS; lengths in m (printed in um).
"""

from __future__ import annotations

import math

import xarray as xr

HOLDS, MARGINAL = 0.05, 0.20  # FA difference (fraction of FA's RMS) where GO holds / is marginal
INVERSIONS = ("go_data", "go_model", "wave_model")  # GO data + GO model; wave data + GO; + wave


def verdict_word(fa_difference: float) -> str:
    """``holds`` (FA within 5 % of its RMS), ``marginal`` (within 20 %) or ``fails``."""
    if not math.isfinite(fa_difference):
        return "unknown"
    return "holds" if fa_difference <= HOLDS else "marginal" if fa_difference <= MARGINAL else "fails"


def verdict_lines(ds: xr.Dataset) -> list[str]:
    """One sentence per frequency: FA, the surface error GO costs, what the wave refinement
    recovers, the gaps; each ending with the verdict word. First the dish's warning, where it
    has one (a mesh file's dish too large for a file in metres)."""
    # the dish's own warning first (a mesh in millimetres read as metres: simulate's warning)
    lines = [str(ds.attrs["dish_warning"])] if ds.attrs.get("dish_warning") else []
    limit = math.degrees(float(ds.attrs["usable_theta_max"]))
    truth_rms = float(ds.attrs.get("truth_rms", math.nan))
    for i, f in enumerate(ds["frequency"].values):
        v = {k: ds[k].values[i] for k in ds.data_vars if ds[k].dims == ("frequency",)}
        word = verdict_word(float(v["fa_difference"]))
        text = (f"at {f / 1e9:g} GHz ({v['wave_method']}) GO {word}: it reproduces FA to "
                f"{100 * v['fa_difference']:.1f} % of its RMS for theta <= {limit:.0f} deg, the ideal "
                f"intensity to {100 * v['ideal_difference']:.1f} %")
        if "cost_go_model" in v:
            text += (f"; the GO assumption costs {1e6 * v['cost_go_model']:.1f} um RMS in the recovered "
                     f"surface ({100 * v['cost_go_model'] / truth_rms:.0f} % of the deformation's "
                     f"{1e6 * truth_rms:.0f} um; error against the truth {1e6 * v['rms_go_model']:.1f} um, "
                     f"RRMS {100 * v['rrms_go_model']:.1f} %, against {1e6 * v['rms_go_data']:.1f} um "
                     "from GO's own data)")
        if "cost_wave_model" in v and math.isfinite(float(v["cost_wave_model"])):
            # "brings that to" read as a gain where the wave refinement cost more
            cost, go_cost = float(v["cost_wave_model"]), float(v.get("cost_go_model", math.nan))
            than = ("" if not math.isfinite(go_cost) else
                    ", less than GO's" if cost < go_cost else ", no less than GO's")
            text += (f"; with the {v['model_wave_model']} refinement the cost is "
                     f"{1e6 * cost:.1f} um{than} (error {1e6 * v['rms_wave_model']:.1f} um, "
                     f"RRMS {100 * v['rrms_wave_model']:.1f} %)")
        lines.append(text + gap_text(ds, i))
    return lines


def gap_text(ds: xr.Dataset, i: int) -> str:
    """The gaps' clause of a verdict line ('' when GO shows no gap line)."""
    dark = int(ds["gap_dark_cells"].values[i])
    if dark == 0:
        return ""
    gap = float(ds.attrs.get("gap", math.nan))
    if math.isfinite(gap) and gap > 0:
        name = f"the {gap * 1e3:g} mm gaps"
    elif int(ds.attrs.get("mesh_pieces", 0)) == 1:  # no gap in one piece: the lines are the facets'
        name = "the mesh's facets (one piece, no gaps)"
    else:
        name = "the mesh's gaps"
    wave_dip, noise = float(ds["gap_wave_dip"].values[i]), float(ds["gap_wave_dip_elsewhere"].values[i])
    seen = "visible in the wave data" if abs(wave_dip) > 2 * noise else "lost in the wave data's ripple"
    share = 100 * dark / int(ds["gap_usable_cells"].values[i])
    return (f"; {name}: GO draws dark lines on {dark} cells ({share:.1f} %)"
            f" at {100 * float(ds['gap_go_dip'].values[i]):+.0f} %, the wave data dip "
            f"{100 * wave_dip:+.2f} % there (elsewhere {100 * noise:.2f} % either way on average): "
            f"{seen}")


def summary_rows(ds: xr.Dataset) -> list[list[str]]:
    """The table across frequencies: header row first, then one row per frequency."""
    head = ["f (GHz)", "wave engine", "ideal diff", "FA diff", "GO", "GO cost (um)",
            "wave-refined cost (um)", "error: GO data / GO-inverted / wave-refined (um)",
            "RRMS GO-inverted", "gap dip GO / wave", "time (s)"]
    rows = [head]
    for i, f in enumerate(ds["frequency"].values):
        def um(name: str, i: int = i) -> str:
            return f"{1e6 * float(ds[name].values[i]):.1f}" if name in ds else "-"

        dark = int(ds["gap_dark_cells"].values[i])
        go_dip, wave_dip = float(ds["gap_go_dip"].values[i]), float(ds["gap_wave_dip"].values[i])
        gaps = (f"{100 * go_dip:+.0f} / {100 * wave_dip:+.2f} %"
                if dark else "-")
        seconds = sum(float(ds[k].values[i]) for k in ds.data_vars if k.startswith("seconds_")
                      and math.isfinite(float(ds[k].values[i])))
        errors = " / ".join(um(f"rms_{n}") for n in INVERSIONS)
        rrms = f"{100 * float(ds['rrms_go_model'].values[i]):.1f} %" if "rrms_go_model" in ds else "-"
        rows.append([f"{f / 1e9:g}", str(ds["wave_method"].values[i]),
                     f"{100 * float(ds['ideal_difference'].values[i]):.2f} %",
                     f"{100 * float(ds['fa_difference'].values[i]):.1f} %",
                     verdict_word(float(ds["fa_difference"].values[i])), um("cost_go_model"),
                     um("cost_wave_model"), errors, rrms, gaps, f"{seconds:.0f}"])
    return rows
