"""PTD benchmark and figures: the time edge diffraction adds to PO, and the checks of issue 6.

Run: ``.venv/bin/python benchmarks/bench_ptd.py [--threads N] [--skip-paper] [--halfplane]
[--convergence] [--gaps] [--out DIR]``.

- default: the fringe kernel's pair rate beside PO's, then the paper case (0.3 GHz, 90 x 360,
  both reflectors): PO alone, then the rim's fringe field, in wall and process CPU time (on a
  shared machine CPU-seconds / threads is the wall time on idle cores), the difference PTD
  makes on the sphere and ``paper_po_ptd.png``.
- ``--halfplane``: PO and PO + PTD against Sommerfeld's half-plane for k rho = 12.6 .. 100
  (the test's reference), as a table and ``halfplane.png``.
- ``--convergence``: the paper case's rim field for 2 .. 8 edge points per wavelength.
- ``--gaps``: the signature of 10 mm panel gaps, I / I(no gaps) - 1: a quadrant map at 0.3 GHz
  and two cuts at 0.3 and 3 GHz; GO (cell means), PO, PO + PTD (all edges, and rim only) and
  PO + PTD for 1 mm gaps (PO's missing strip scaled from 10 mm); ``gaps_map_0.3GHz.png``,
  ``gaps_cuts_<f>GHz.png`` and numbers.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_po import Clock  # noqa: E402  (wall and CPU time of a block, shared with the PO benchmark)

D, F, R = 110.0, 33.0, 10.0
RINGS = (0.0, 6.875, 13.75, 20.625, 27.5, 34.375, 41.25, 48.125, 55.0)
PANELS = (6, 12, 18, 24, 30, 36, 42, 48)


def kernel_rates(threads: int) -> None:
    """Fringe kernel and PO kernel on 32 400 sphere points, the paper dish's rim at 0.3 GHz."""
    from raysim.maps.sphere import SphereGrid
    from raysim.optics import po, ptd
    from raysim.surface.edges import edge_quadrature
    from raysim.surface.mesh import paraboloid
    from raysim.surface.quadrature import plan

    wave = po.Illumination.plane_wave(0.3e9, (0, 0, -1), (1, 0, 0))
    dish = paraboloid(D, F, 5.0)
    points = SphereGrid(R).points(F).reshape(-1, 3)
    edges = ptd.fringe_elements(edge_quadrature(dish, wave.wavelength / 4.0, "rim"), wave)
    po.Radiator(points[:8], wave.k).add_packed(edges, "fringe")  # compile or load
    radiator = po.Radiator(points, wave.k)
    with Clock() as c:
        radiator.add_packed(edges, "fringe")
    print(f"fringe kernel: {len(points):,} points x {edges.shape[1]:,} edge points = {radiator.pairs:,} "
          f"pairs, {threads} thread(s): wall {c.wall:.2f} s, {radiator.pairs / c.cpu / 1e6:.1f} M pairs "
          f"per CPU-second")
    src = next(po.po_elements(dish, wave, plan(dish, wave.wavelength, 1.5), chunk=4096))
    po.Radiator(points[:8], wave.k).add_packed(src)
    rad = po.Radiator(points, wave.k)
    with Clock() as c:
        rad.add_packed(src)
    print(f"PO kernel:     {rad.pairs:,} pairs: {rad.pairs / c.cpu / 1e6:.1f} M pairs per CPU-second")


def paper_case(threads: int, out: Path) -> None:
    """PO of both reflectors, then the rim's fringe field of both: what PTD adds, in time and
    on the sphere (``paper_po_ptd.png``)."""
    from raysim.maps.sphere import ideal_go_intensity
    from raysim.optics import po, ptd
    from raysim.scene.scene import load_scene
    from raysim.simulate import simulate
    from raysim.surface.mesh import reflectors_for

    scene = load_scene(ROOT / "scenes" / "paper_po.toml")
    with Clock() as c_po:
        ds = simulate(scene, method="po", save_field=True)
    ideal, deformed = reflectors_for(scene)
    wave = po.Illumination.plane_wave(scene.source.frequency_hz, scene.source.direction, scene.source.e_hat)
    with Clock() as c_ptd:
        edge = {name: ptd.sphere_edge_field(r, scene.sphere, wave, "rim")
                for name, r in (("ideal", ideal), ("deformed", deformed))}
    pairs = sum(r.pairs for r in edge.values())
    print(f"paper case (0.3 GHz, 90 x 360, ideal + deformed), {threads} thread(s):")
    print(f"  PO:          {ds.attrs['pairs']:,} pairs, wall {c_po.wall:7.1f} s, CPU {c_po.cpu:7.1f} s "
          f"-> {c_po.cpu / threads:6.1f} s on {threads} idle core(s)")
    print(f"  PTD (rim):   {edge['ideal'].n_points:,} edge points, {pairs:,} pairs, "
          f"wall {c_ptd.wall:6.1f} s, CPU {c_ptd.cpu:6.1f} s -> {c_ptd.cpu / threads:5.1f} s on "
          f"{threads} idle core(s)")
    print(f"  PTD adds {100 * c_ptd.cpu / c_po.cpu:.1f} % to PO's CPU time")

    def field(name):
        return ds[f"{name}_re"].values + 1j * ds[f"{name}_im"].values

    I_po = {"ideal": np.sum(np.abs(field("E_ideal")) ** 2, -1),
            "deformed": np.sum(np.abs(field("E")) ** 2, -1)}
    I_ptd = {"ideal": np.sum(np.abs(field("E_ideal") + edge["ideal"].E) ** 2, -1),
             "deformed": np.sum(np.abs(field("E") + edge["deformed"].E) ** 2, -1)}
    FA_po = I_po["ideal"] / I_po["deformed"] - 1.0
    FA_ptd = I_ptd["ideal"] / I_ptd["deformed"] - 1.0
    theta = np.degrees(scene.sphere.theta)
    print("  PO vs PO+PTD on the sphere (deformed dish), rms over the cells of each theta band:")
    for lo, hi in ((0, 20), (20, 40), (40, 60), (60, 79.6), (79.6, 90)):
        m = (theta >= lo) & (theta < hi)
        rel = I_ptd["deformed"][m] / I_po["deformed"][m] - 1.0
        print(f"    theta {lo:4g}..{hi:4g} deg: |I_ptd / I_po - 1| rms {np.sqrt(np.mean(rel**2)):.2e} "
              f"max {np.abs(rel).max():.2e}; FA change rms {np.sqrt(np.mean((FA_ptd - FA_po)[m] ** 2)):.2e} "
              f"(FA itself rms {np.sqrt(np.mean(FA_ptd[m] ** 2)):.2e})")
    import matplotlib.pyplot as plt

    law = ideal_go_intensity(scene.sphere.theta, F, R)
    fig, axes = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for j, style in ((0, "-"), (90, "--")):
        cut = f"phi {j + 0.5:g} deg"
        axes[0].plot(theta, I_po["ideal"][:, j] / law, "C0" + style, lw=1, label=f"PO, {cut}")
        axes[0].plot(theta, I_ptd["ideal"][:, j] / law, "C3" + style, lw=1, label=f"PO+PTD, {cut}")
        axes[1].plot(theta, FA_po[:, j], "C0" + style, lw=1, label=f"PO, {cut}")
        axes[1].plot(theta, FA_ptd[:, j], "C3" + style, lw=1, label=f"PO+PTD, {cut}")
    axes[0].axhline(1.0, color="k", lw=0.6, label="GO")
    axes[0].set_ylabel("ideal dish: I / (rho / R)^2")
    axes[1].set_ylabel("FA = I_ideal / I_def - 1")
    axes[1].set_xlabel("theta (deg)")
    for ax in axes:
        ax.axvline(np.degrees(2 * np.arctan(D / (4 * F))), color="grey", lw=0.6)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[0].set_title("Paper case, 0.3 GHz: PO and PO + PTD (rim) on the probe sphere", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "paper_po_ptd.png", dpi=120)
    plt.close(fig)
    print(f"  wrote {out / 'paper_po_ptd.png'}")


def halfplane(out: Path) -> None:
    """PO and PO + PTD errors against the exact half-plane, and the figure."""
    sys.path.insert(0, str(ROOT / "tests" / "raysim"))
    import test_ptd_halfplane as hp

    rows = []
    for name, plate, k_hat, e_hat in [
        ("normal, E along the edge", hp.plate(22.0, 16.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
        ("normal, E across the edge", hp.plate(22.0, 16.0), (0.0, 0.0, -1.0), (1.0, 0.0, 0.0)),
        ("skew b' 50, p' 60, soft", hp.plate(40.0, 25.0), *hp.oblique(False)),
        ("skew b' 50, p' 60, hard", hp.plate(40.0, 25.0), *hp.oblique(True)),
    ]:
        e_po, e_ptd, _, _ = hp.errors(*plate, np.asarray(k_hat, float), np.asarray(e_hat, float))
        rows.append((name, e_po, e_ptd))
    k_rho = 2 * np.pi * hp.RHO / hp.LAMBDA
    print("half-plane, max over 14 directions of |E - E_exact| (incident = 1); in brackets the "
          "directions 45..315 deg from the plate")
    print(f"{'case':28s} " + " ".join(f"{'k rho ' + format(k, '.1f'):>22s}" for k in k_rho))
    for name, e_po, e_ptd in rows:
        print(f"{name + ', PO':28s} " + " ".join(f"{v:22.2e}" for v in e_po.max(axis=1)))
        print(f"{name + ', PO+PTD':28s} " + " ".join(
            f"{a:11.2e} [{b:8.2e}]" for a, b in zip(e_ptd.max(axis=1), e_ptd[:, hp.AWAY].max(axis=1),
                                                    strict=True)))
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    for (name, e_po, e_ptd), colour in zip(rows, ("C0", "C1", "C2", "C3"), strict=True):
        ax.loglog(k_rho, e_po.max(axis=1), "--", color=colour, label=f"PO, {name}")
        ax.loglog(k_rho, e_ptd.max(axis=1), "-o", color=colour, label=f"PO+PTD, {name}")
    ax.loglog(k_rho, 0.3 * k_rho**-0.5, ":", color="grey", label="(k rho)^-1/2, (k rho)^-3/2")
    ax.loglog(k_rho, 0.1 * k_rho**-1.5, ":", color="grey")
    ax.set_xlabel("k rho (distance from the edge)")
    ax.set_ylabel("max |E - E_exact| / |E_inc|")
    ax.set_title("Straight edge of a large plate vs Sommerfeld's half-plane")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "halfplane.png", dpi=120)
    print(f"wrote {out / 'halfplane.png'}")


def convergence() -> None:
    """The paper dish's rim field on 90 x 36 points for 2 .. 8 edge points per wavelength."""
    from raysim.maps.sphere import SphereGrid
    from raysim.optics import po, ptd
    from raysim.surface.mesh import paraboloid

    dish, grid = paraboloid(D, F, 5.0), SphereGrid(R, 90, 36)
    wave = po.Illumination.plane_wave(0.3e9, (0, 0, -1), (1, 0, 0))
    fields = {n: ptd.sphere_edge_field(dish, grid, wave, "rim", n).E for n in (2.0, 3.0, 4.0, 6.0, 8.0)}
    ref = fields[8.0]
    scale = np.abs(ref).max()
    for n, E in fields.items():
        print(f"  {n:3g} edge points per wavelength: max |E - E(8)| / max |E(8)| "
              f"{np.abs(E - ref).max() / scale:.1e}")


def po_field(reflector, points, wave, spw: float = 1.5):
    """PO field (n, 3) of ``reflector`` at ``points`` (the engine of raysim.optics.po)."""
    from raysim.optics import po

    return po.scatter(reflector, points, wave, spw).E


def gap_fields(gapped, smooth, thin, P, wave) -> dict[str, np.ndarray]:
    """I / I(no gaps) - 1 at points P for PO, PO + PTD (all edges, rim only) and PO + PTD for
    1 mm gaps (PO's missing strip, linear in its width, scaled from 10 mm)."""
    from raysim.optics import ptd

    E_gap, E_ref = po_field(gapped, P, wave), po_field(smooth, P, wave)
    edge_all = ptd.edge_field(gapped, P, wave, "all").E
    edge_rim = ptd.edge_field(gapped, P, wave, "rim").E
    edge_ref = ptd.edge_field(smooth, P, wave, "rim").E
    edge_thin = ptd.edge_field(thin, P, wave, "all").E

    def intensity(E):
        return np.sum(np.abs(E) ** 2, axis=1)

    I_ref_po, I_ref = intensity(E_ref), intensity(E_ref + edge_ref)
    return {
        "PO": intensity(E_gap) / I_ref_po - 1.0,
        "PO+PTD, all edges": intensity(E_gap + edge_all) / I_ref - 1.0,
        "PO+PTD, 1 mm gaps": intensity(E_ref + 0.1 * (E_gap - E_ref) + edge_thin) / I_ref - 1.0,
        "PO + rim PTD (gap edges left out)": intensity(E_gap + edge_rim) / I_ref - 1.0,
    }


def go_signature(layout, grid):
    """GO cell means of the panelled dish over the ideal law's cell means, minus 1."""
    from raysim.maps.sphere import ideal_go_cell_mean
    from raysim.optics import go
    from raysim.surface.mesh import paraboloid

    cell = go.trace(paraboloid(D, F, 0.5, layout), grid, subdivisions=2).intensity
    e = grid.theta_edges
    law = ideal_go_cell_mean(e[:-1], e[1:], F, R, D)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(law > 0, cell / law - 1.0, np.nan)


def summary(label: str, s: np.ndarray) -> str:
    return (f"  {label:34s} min {s.min():+.2e}  max {s.max():+.2e}  rms {np.sqrt(np.mean(s**2)):.2e}  "
            f"mean {s.mean():+.2e}")


def gaps(out: Path, frequencies=(0.3e9, 3e9)) -> None:
    """Gap signatures: a quadrant map at 0.3 GHz (1 deg cells), and at each frequency a phi cut
    (theta 40 deg) across radial gaps and a theta cut (phi 4 deg) across ring gaps."""
    import matplotlib.pyplot as plt

    from raysim.maps.sphere import SphereGrid, theta_rim
    from raysim.optics import po
    from raysim.surface.mesh import paraboloid
    from raysim.surface.panels import PanelLayout

    layout, thin = PanelLayout(RINGS, PANELS, 0.010), PanelLayout(RINGS, PANELS, 0.001)
    gapped, smooth, thin_dish = (paraboloid(D, F, 2.5, layout), paraboloid(D, F, 5.0),
                                 paraboloid(D, F, 2.5, thin))
    # --- the quadrant map at 0.3 GHz
    wave = po.Illumination.plane_wave(0.3e9, (0, 0, -1), (1, 0, 0))
    grid = SphereGrid(R, 90, 90, 0.0, np.pi / 2, 0.0, np.pi / 2)
    with Clock() as c:
        sig = gap_fields(gapped, smooth, thin_dish, grid.points(F).reshape(-1, 3), wave)
    maps = {"GO (1 deg cell means)": go_signature(layout, grid)}
    maps.update({k: v.reshape(grid.n_theta, grid.n_phi) for k, v in sig.items()})
    inside = grid.theta < theta_rim(D, F) - np.radians(1.0)
    print(f"0.3 GHz, quadrant map (90 x 90 points, theta < rim image - 1 deg; {c.wall:.0f} s): "
          "I / I(no gaps) - 1")
    for label, m in maps.items():
        print(summary(label, m[inside]))
    fig, axes = plt.subplots(1, 4, figsize=(17, 4.6), sharey=True)
    extent = (0, 90, 90, 0)
    panels = ["GO (1 deg cell means)", "PO", "PO+PTD, all edges", "PO+PTD, 1 mm gaps"]
    for ax, label, limit in zip(axes, panels,
                                (0.05, 0.02, 0.1, 0.1), strict=True):
        image = ax.imshow(maps[label], extent=extent, aspect="auto", cmap="RdBu_r", vmin=-limit, vmax=limit)
        ax.set_title(f"{label}", fontsize=9)
        ax.set_xlabel("phi (deg)")
        fig.colorbar(image, ax=ax, shrink=0.85)
    axes[0].set_ylabel("theta (deg); colour: I / I(no gaps) - 1")
    fig.suptitle("0.3 GHz, 10 mm gaps (1 mm where stated), one quadrant of the sphere", fontsize=10)
    path = out / "gaps_map_0.3GHz.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"wrote {path}")
    # --- cuts
    step = 0.05
    cuts = {
        "phi cut at theta 40 deg": (SphereGrid(R, 1, int(20 / step), np.radians(39.5), np.radians(40.5), 0.0,
                                               np.radians(20.0)), None),
        # GO needs more than one phi cell here: 4 cells of 1 deg, the cut is the second
        "theta cut at phi 4 deg": (SphereGrid(R, int(30 / step), 1, np.radians(30.0), np.radians(60.0),
                                              np.radians(3.5), np.radians(4.5)),
                                   SphereGrid(R, int(30 / step), 4, np.radians(30.0), np.radians(60.0),
                                              np.radians(2.5), np.radians(6.5))),
    }
    go_cut = {}
    for name, (grid, go_grid) in cuts.items():
        go_cut[name] = go_signature(layout, grid).ravel() if go_grid is None else \
            go_signature(layout, go_grid)[:, 1]
    for f in frequencies:
        wave = po.Illumination.plane_wave(f, (0, 0, -1), (1, 0, 0))
        fig, axes = plt.subplots(2, 1, figsize=(9, 7))
        for ax, (name, (grid, _)) in zip(axes, cuts.items(), strict=True):
            P = grid.points(F).reshape(-1, 3)
            with Clock() as c:
                sig = {"GO (0.05 deg cells)": go_cut[name], **gap_fields(gapped, smooth, thin_dish, P, wave)}
            x = np.degrees(grid.phi if grid.n_phi > 1 else grid.theta)
            print(f"{f / 1e9:g} GHz, {name} ({len(P)} points, {c.wall:.0f} s): I / I(no gaps) - 1")
            for (label, s), style in zip(sig.items(), ("k-", "C0-", "C3-", "C1--", "C2:"), strict=True):
                print(summary(label, s))
                ax.plot(x, s, style, lw=0.7 if label.startswith("GO") else 1.2, label=label)
            ax.set_ylim(-0.12, 0.12)
            ax.set_xlabel(name.split()[0] + " (deg)")
            ax.set_ylabel("I / I(no gaps) - 1")
            ax.set_title(f"{f / 1e9:g} GHz, {name}, 10 mm gaps (GO's dips reach -0.3, clipped)", fontsize=9)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="lower right")
        fig.tight_layout()
        path = out / f"gaps_cuts_{f / 1e9:g}GHz.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        print(f"wrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=None, help="CPU threads (default: all cores)")
    parser.add_argument("--skip-paper", action="store_true", help="kernel rates only")
    parser.add_argument("--halfplane", action="store_true", help="accuracy against the exact half-plane")
    parser.add_argument("--convergence", action="store_true", help="edge points per wavelength")
    parser.add_argument("--gaps", action="store_true", help="panel-gap signatures at 0.3 and 3 GHz (slow)")
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "ptd", help="folder for the PNGs")
    args = parser.parse_args()
    if args.threads:
        os.environ["RAYSIM_THREADS"] = str(args.threads)
    from raysim.optics.runtime import cpu_threads

    threads = cpu_threads()
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())} "
          f"(over {os.cpu_count()} cores: more means other jobs share them)")
    kernel_rates(threads)
    if not args.skip_paper:
        paper_case(threads, args.out)
    if args.halfplane:
        halfplane(args.out)
    if args.convergence:
        convergence()
    if args.gaps:
        gaps(args.out)
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
