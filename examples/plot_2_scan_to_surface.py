"""
From a scan to a surface map
============================

The whole measurement chain on the paper's 110 m dish, with the truth known: simulate the
deformed dish, scan it with the simulated rig (the real PyVISA drivers talking to simulated
instruments on loopback sockets, with noise and drift), invert the measured scan, and write
the report. The same on the command line::

    raysim simulate tutorial.toml -o field.nc
    raysim scan plan.toml --simulate field.nc -o scan.nc
    raysim invert scan.nc -o surface.nc --grid 64
    raysim report scan.nc -o report --grid 64

To keep it to seconds the mesh is coarse (1 m triangles), the sphere 30 x 60 cells and the
scan plan 32 x 36 points of 4 readings each.
"""

# %%
# Simulate
# --------
# A scene is TOML; every key carries its unit. The deformation is the paper's Eq. 8.
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

import raysim
import solver
from hardware.session import scan_files
from raysim.files import example
from raysim.pipeline.report import report
from raysim.surface.deformation import PaperDeformation

work = Path(tempfile.mkdtemp(prefix="raysim-tutorial-"))
scene_file = work / "tutorial.toml"
scene_file.write_text("""
name = "tutorial"
[dish]
diameter_m = 110.0
focal_length_m = 33.0
resolution_m = 1.0
[[deformation]]
type = "paper"
[source]
frequency_hz = 0.3e9
[sphere]
radius_m = 10.0
n_theta = 30
n_phi = 60
""")
field = raysim.simulate(raysim.load_scene(scene_file), method="go")
raysim.save_fieldmap(field, work / "field.nc")
print(field["intensity"].shape, "cells; intensity from", float(field["intensity"].min()),
      "to", float(field["intensity"].max()))

# %%
# Scan with the simulated rig
# ---------------------------
# The plan gives the grid (here 2.5 x 10 degree cells), the readings per point and the drift
# references; the rig file (the shipped ``rig``) the track radius (10 m, the sphere's). Every
# sample is journaled before the next move, so a stopped scan resumes.
plan = work / "plan.toml"
plan.write_text(f"""
description = "tutorial: 2.5 x 10 deg cells over the paper's dish"
rig = "{example('rig')}"
[reflector]
focal_length_m = 33.0
diameter_m = 110.0
frequency_hz = 0.3e9
[grid]
theta_min_deg = 0.0
theta_max_deg = 80.0
theta_step_deg = 2.5
phi_min_deg = 0.0
phi_max_deg = 360.0
phi_step_deg = 10.0
[acquisition]
samples_per_point = 4
reference_every_lines = 3
reference_samples = 64
drift_correction = "auto"
[simulator]
seed = 1
noise_db = 0.001
drift_db = 0.005
time_scale = 0.0
""")
result = scan_files(plan, work / "scan.nc", simulate=work / "field.nc")
scan = result.fieldmap
print(f"{scan.attrs['samples_measured']} samples measured; method = {scan.attrs['method']}")

# %%
# Invert
# ------
# A measured scan's gain is unknown: it is estimated, and the one shape it hides (delta_c) is
# removed and recorded. Without rim targets the harmonic part is assumed zero on the rim.
# A measured scan carries no scene, so the truth (Eq. 8) is passed to get the error figures.
truth = PaperDeformation(110.0, 33.0, 1.0)
surface = solver.invert(scan, N=64, refine_iterations=2, truth=truth)
ideal = solver.invert(field, N=64, refine_iterations=2)
for name, ds in [("scan (noise and drift)", surface), ("clean simulated field", ideal)]:
    print(f"{name}: RMS error {ds.attrs['rms_m'] * 1e6:.1f} um, RRMS {100 * ds.attrs['rrms']:.2f} %")

fig, axes = plt.subplots(1, 2, figsize=(9, 4), layout="constrained")
for ax, (title, ds) in zip(axes, [("from the scan", surface),
                                  ("from the 30 x 60 cell simulation", ideal)], strict=True):
    im = ax.pcolormesh(ds["x"], ds["y"], 1e6 * ds["deformation"], shading="auto", cmap="viridis")
    ax.set(title=title, xlabel="x (m)", ylabel="y (m)", aspect="equal")
    fig.colorbar(im, ax=ax, label="delta (um, along +z)")
plt.show()

# %%
# Report
# ------
# One self-contained HTML page with the paper's figures for this run (Figs. 8-10).
page = report(work / "field.nc", work / "report", grid=64, refine=1)
print(page.name, f"{page.stat().st_size / 1e3:.0f} kB")
