"""Mesh-file benchmark: the paper's dish written as a file, loaded and traced by GO.

Run: ``.venv/bin/python benchmarks/bench_mesh_file.py [--resolution 0.35] [--panels]``.

Writes raysim's own 110 m dish (F = 33 m; 78 panels with 10 mm gaps with ``--panels``) with a
200 um Gaussian bump in its vertices to an OBJ of 10 decimals (a float32 binary PLY with
``--float32``), then times, on this machine, loading
it (the fit, the checks, the departure's vertex gradients) and ``raysim simulate --method go``
on the paper's 90 x 360 sphere, beside the same dish and bump as a scene (its smooth surface
given analytically). It reports how far the file's FA is from the scene's, in units of FA's
RMS over the cells inside the rim image: what a user's file costs in time and in accuracy.
With ``--panels`` part of that difference is real: the file's ring gaps are chords of its
triangles (2 mm inside the scene's arcs at the inner ring), which move GO's dark gap lines.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

D, F, R = 110.0, 33.0, 10.0
BUMP = (20.0, 5.0, 200e-6, 5.0)  # x, y, amplitude, sigma (m)
PANELS = ("[panels]\nring_edges_m = [0.0, 6.875, 13.75, 27.5, 55.0]\npanels_per_ring = [6, 12, 24, 36]\n"
          "gap_m = 0.01\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=float, default=0.35, help="triangle edge (m)")
    parser.add_argument("--panels", action="store_true", help="78 panels with 10 mm gaps")
    parser.add_argument("--float32", action="store_true", help="a binary PLY (float32), not an OBJ")
    args = parser.parse_args()

    import numpy as np
    import trimesh

    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate
    from raysim.surface.mesh import load_reflector, reflectors_for

    x0, y0, a, s = BUMP
    sphere = f"[source]\nfrequency_hz = 1e9\n[sphere]\nradius_m = {R}\nn_theta = 90\nn_phi = 360\n"
    bump = (f'[[deformation]]\ntype = "bumps"\nbumps = [{{x_m = {x0}, y_m = {y0}, '
            f"amplitude_um = {a * 1e6}, sigma_m = {s}}}]\n")
    panels = PANELS if args.panels else ""
    scene_text = (f'name = "scene"\n[dish]\ndiameter_m = {D}\nfocal_length_m = {F}\n'
                  f"resolution_m = {args.resolution}\n{panels}{sphere}{bump}")
    with tempfile.TemporaryDirectory() as folder:
        base = Path(folder)
        scene = parse_scene(scene_text, source=str(base / "scene.toml"), base=base)
        _, deformed = reflectors_for(scene)
        # float32 (binary PLY) rounds a 110 m dish's z to ~2 um, which GO reads as roughness
        path = base / ("dish.ply" if args.float32 else "dish.obj")
        written = trimesh.Trimesh(deformed.vertices, deformed.faces, process=False)
        written.export(path, **({"encoding": "binary"} if args.float32 else {"digits": 10}))
        print(f"{path.name}: {len(deformed.faces):,} faces, {deformed.n_panels} pieces")
        start = time.perf_counter()
        load_reflector(path, F=F)
        print(f"load: {time.perf_counter() - start:.2f} s")
        mesh = parse_scene(f'name = "file"\n[dish]\nmesh = "{path.name}"\nfocal_length_m = {F}\n{sphere}',
                           source=str(base / "file.toml"), base=base)
        simulate(mesh, method="go")  # compile or load the kernels
        fa = {}
        for name, which in (("file", mesh), ("scene", scene)):
            start = time.perf_counter()
            ds = simulate(which, method="go")
            print(f"simulate --method go, {name}: {time.perf_counter() - start:.2f} s")
            with np.errstate(invalid="ignore", divide="ignore"):
                fa[name] = ds.intensity_ideal.values / ds.intensity.values - 1.0
        theta = ds.theta.values
        rim = 2.0 * np.arctan(D / (4.0 * F))
        use = np.broadcast_to((theta < rim - np.radians(2))[:, None], fa["scene"].shape)
        use = use & np.isfinite(fa["file"]) & np.isfinite(fa["scene"])
        off = np.sqrt(np.mean((fa["file"] - fa["scene"])[use] ** 2) / np.mean(fa["scene"][use] ** 2))
        print(f"FA of the file against the scene's: {off:.3f} of its RMS ({use.sum()} cells)")


if __name__ == "__main__":
    main()
