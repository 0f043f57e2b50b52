"""go+edge benchmark and figures (issue 15): agreement with PO + PTD, cost against frequency,
Table 3 with the go+edge refinement, the panel gaps.

Run: ``.venv/bin/python benchmarks/bench_goedge.py [--compare [CASE ...]] [--cost] [--table3]
[--panels] [--threads N] [--fresnel]`` (default: all four; ``--fresnel`` runs go+edge with its
Fresnel-zone correction, :mod:`raysim.optics.fresnel`). The PO + PTD references are the cached FieldMaps
of ``benchmarks/goedge_cases.py`` (``out/goedge_ref/``; a missing one is simulated first, which
takes hours for the large cases: run that script alone, with ``nice``, beforehand).

- ``--compare``: each case's go+edge map beside PO + PTD's: the ideal intensity's RMS relative
  difference and FA = I_ideal / I_def - 1's RMS difference over FA's RMS, for theta up to the
  rim image minus 2 deg, with both engines' times.
- ``--cost``: the paper's dish (D = 110 m, F = 33 m, R = 10 m, 5 m faces, Eq. 8) on 90 x 360,
  ideal and deformed, 0.3 to 12 GHz: go+edge wall time (trace, edges, total) beside PO + PTD's
  measured (the cached references' own time) or extrapolated (x f^2 from the 1 GHz run).
- ``--table3``: the paper's Table 3 rows at 1 and 3 GHz with PO + PTD (rim) data (90 x 360 and
  90 x 36), inverted by the default solver with the go+edge refinement: RRMS and time.
- ``--panels``: scenes/panels_ptd.toml at 3 GHz on the sector phi 0..60 deg: go+edge and GO
  beside PO + PTD (all edges), the same measures, and the depth of the gap lines.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from goedge_cases import CASES, PAPER, Case, reference  # noqa: E402


def measures(ds, ref) -> tuple[float, float]:
    """(ideal RMS relative difference, FA RMS difference / FA RMS) for theta <= rim - 2 deg."""
    th = np.degrees(ds.theta.values)
    rim = np.degrees(2.0 * np.arctan(ds.attrs["diameter"] / (4.0 * ds.attrs["focal_length"])))
    use = th <= rim - 2.0
    i0, i1 = ds["intensity_ideal"].values[use], ds["intensity"].values[use]
    r0, r1 = ref["intensity_ideal"].values[use], ref["intensity"].values[use]
    ideal = float(np.sqrt(np.mean(((i0 - r0) / r0) ** 2)))
    fa, fa_ref = i0 / i1 - 1.0, r0 / r1 - 1.0
    return ideal, float(np.sqrt(np.mean((fa - fa_ref) ** 2) / np.mean(fa_ref**2)))


FRESNEL = False  # --fresnel: go+edge with its Fresnel-zone correction (raysim.optics.fresnel)


def go_edge(case: Case, cpu: list | None = None):
    """The go+edge FieldMap of ``case`` and its wall time (s); ``cpu`` collects CPU seconds."""
    from raysim.simulate import simulate

    start, start_cpu = time.perf_counter(), time.process_time()
    ds = simulate(case.scene(), method="go+edge", fresnel=FRESNEL)
    if cpu is not None:
        cpu.append(time.process_time() - start_cpu)
    return ds, time.perf_counter() - start


def compare(names: list[str]) -> None:
    print("case            grid      PO+PTD s  go+edge s  ideal RMS   FA err / FA RMS   FA RMS")
    for name in names:
        case = CASES[name]
        ref = reference(case, log=print)
        ds, seconds = go_edge(case)
        ideal, fa = measures(ds, ref)
        th = np.degrees(ref.theta.values)
        rim = np.degrees(2.0 * np.arctan(ref.attrs["diameter"] / (4.0 * ref.attrs["focal_length"])))
        use = th <= rim - 2.0
        fa_ref = ref["intensity_ideal"].values / ref["intensity"].values - 1
        fa_rms = float(np.sqrt(np.mean(fa_ref[use] ** 2)))
        print(f"{name:15s} {case.n_theta}x{case.n_phi:<6d} {ref.attrs['seconds_total']:9.0f} {seconds:10.1f} "
              f"{100 * ideal:9.3f} % {100 * fa:12.2f} %   {fa_rms:.3g}", flush=True)


def cost(frequencies=(0.3e9, 1e9, 3e9, 6e9, 12e9)) -> None:
    measured = {}
    for f in (0.3e9, 1e9, 3e9):
        path = Case("", PAPER, f).path
        if path.is_file():
            from raysim.maps.fieldmap import load

            measured[f] = float(load(path).attrs["seconds_total"])
    base_f = max((f for f in measured if f <= 1e9), default=None)
    print("f (GHz)  trace s  edges s  go+edge total s  CPU s / 2  edge points   PO+PTD s (90 x 360)")
    for f in frequencies:
        cpu: list = []
        ds, seconds = go_edge(Case("cost", PAPER, f), cpu)
        if f in measured and Case("", PAPER, f).path.is_file():
            po_text = f"{measured[f]:.0f} measured"
        elif base_f is not None:
            po_text = f"{measured[base_f] * (f / base_f) ** 2:.0f} extrapolated (x f^2)"
        else:
            po_text = "-"
        print(f"{f / 1e9:7.1f} {ds.attrs['seconds_trace']:8.1f} {ds.attrs['seconds_edges']:8.1f} "
              f"{seconds:16.1f} {cpu[0] / 2:10.1f} {ds.attrs['edge_points']:12,d}   {po_text}", flush=True)


def table3() -> None:
    from raysim.surface.deformation import PaperDeformation
    from solver.invert import DEFAULT_REFINE, invert

    truth = PaperDeformation(110.0, 33.0, 1.0)
    print("f (GHz)  grid     paper RRMS  linear (paper setting)  GO refine  go+edge refine  "
          "time (s)")
    paper = {1e9: 0.0506, 3e9: 0.0642}
    for name in ("paper_1GHz", "paper_3GHz"):
        case = CASES[name]
        field = reference(case, log=print)
        linear = invert(field, N=256, truth=truth, solver="gauss-seidel", iterations=1000,
                        refine_iterations=0)
        go = invert(field, N=256, truth=truth, refine_iterations=DEFAULT_REFINE, model="go")
        start = time.perf_counter()
        wave = invert(field, N=256, truth=truth, refine_iterations=DEFAULT_REFINE, model="go+edge")
        seconds = time.perf_counter() - start
        print(f"{case.frequency_hz / 1e9:7.0f}  {case.n_theta}x{case.n_phi:<6d} "
              f"{100 * paper[case.frequency_hz]:8.2f} % "
              f"{100 * float(linear.attrs['rrms']):14.2f} % {100 * float(go.attrs['rrms']):12.2f} % "
              f"{100 * float(wave.attrs['rrms']):12.2f} % {seconds:10.0f}", flush=True)


def panels() -> None:
    from raysim.simulate import simulate

    case = CASES["panels_3GHz"]
    ref = reference(case, log=print)
    ds, seconds = go_edge(case)
    go = simulate(case.scene(), method="go")
    ideal, _ = measures(ds, ref)
    print(f"panels_ptd 3 GHz, {case.n_theta} x {case.n_phi} (phi 0..60 deg): go+edge {seconds:.0f} s, "
          f"PO+PTD {ref.attrs['seconds_total']:.0f} s; go+edge against PO+PTD: 'ideal' (the gapped "
          f"dish itself) {100 * ideal:.2f} % RMS")
    # the gap lines: cells whose intensity GO finds darkened by a gap (cell mean below 99 % of
    # the smooth GO value), and the same cells in the wave maps
    from raysim.maps.sphere import ideal_go_cell_mean

    e = ds.theta.values
    dth = e[1] - e[0]
    smooth = ideal_go_cell_mean(e - dth / 2, e + dth / 2, 33.0, 10.0)[:, None]
    go_rel = go["intensity_ideal"].values / smooth
    rim = np.degrees(2.0 * np.arctan(110.0 / (4.0 * 33.0)))
    use = (np.degrees(e) <= rim - 2.0)[:, None] & np.ones_like(go_rel, dtype=bool)
    dark = use & (go_rel < 0.99)
    for label, I in (("GO (cell means)", go["intensity_ideal"].values),
                     ("go+edge", ds["intensity_ideal"].values), ("PO+PTD", ref["intensity_ideal"].values)):
        rel = I / smooth
        print(f"  {label:16s} on GO's dark cells ({int(dark.sum())}): mean I / I_smooth "
              f"{rel[dark].mean():.4f}, elsewhere {rel[use & ~dark].mean():.4f}")
    i_ge, i_po = ds["intensity_ideal"].values, ref["intensity_ideal"].values
    print(f"  go+edge against PO+PTD on GO's dark cells: RMS relative "
          f"{100 * np.sqrt(np.mean(((i_ge - i_po) / i_po)[dark] ** 2)):.2f} %")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--compare", nargs="*", default=None)
    parser.add_argument("--cost", action="store_true")
    parser.add_argument("--table3", action="store_true")
    parser.add_argument("--panels", action="store_true")
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--fresnel", action="store_true",
                        help="--compare / --cost: go+edge with its Fresnel-zone correction")
    args = parser.parse_args()
    global FRESNEL
    FRESNEL = args.fresnel
    if args.threads:
        os.environ["RAYSIM_THREADS"] = str(args.threads)
    everything = args.compare is None and not (args.cost or args.table3 or args.panels)
    if args.compare is not None or everything:
        compare(args.compare or [n for n in CASES if n != "panels_3GHz"])
    if args.cost or everything:
        cost()
    if args.table3 or everything:
        table3()
    if args.panels or everything:
        panels()


if __name__ == "__main__":
    main()
