"""
Is GO good enough for my dish?
==============================

``raysim check`` answers it for a dish you bring as a mesh file: it fits the file to its
paraboloid, finds the panels (the mesh's separate pieces), and compares the geometric-optics
(GO) intensity with a wave engine's (PO + PTD here) at each frequency, then inverts both with
GO to show what the GO assumption costs in surface error.

Here the dish is small (D = 10 m, F = 3 m, 36 panels in three rings with 20 mm gaps), written
to an STL file first, so that the whole check takes seconds. On the command line the same is
``raysim check panelled.stl --frequency 1e9 --frequency 4e9 --sphere-radius 1 --sphere 24x36
--grid 64 --wave po+ptd --refine-model none -o out/check``.
"""

# %%
# A panelled dish as an STL file
# ------------------------------
# :func:`raysim.surface.mesh.paraboloid` builds the triangulated reflector (metres, vertex at
# the origin, axis +z); trimesh writes it. Any STL, PLY, OBJ or GLB of a dish works the same.
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import trimesh

from raysim.pipeline.check import write_check
from raysim.pipeline.check_verdict import summary_rows, verdict_lines
from raysim.surface.mesh import paraboloid
from raysim.surface.panels import PanelLayout

work = Path(tempfile.mkdtemp(prefix="raysim-tutorial-"))
layout = PanelLayout((0.0, 1.7, 3.4, 5.0), (6, 12, 18), 0.02)  # ring edges (m), panels, gap (m)
dish = paraboloid(10.0, 3.0, 0.1, layout)                     # D, F, triangle edge (m)
stl = work / "panelled.stl"
trimesh.Trimesh(dish.vertices, dish.faces, process=False).export(stl)
print(f"{stl.name}: {len(dish.faces)} triangles, {stl.stat().st_size / 1e6:.1f} MB")

# %%
# The check at two frequencies
# ----------------------------
# The probe sphere is 1 m in radius around the fitted focus, 24 x 36 cells; the inversions use
# a 64-point aperture grid (the default is 256).
page, ds = write_check(stl, work / "check", frequencies=[1e9, 4e9], sphere_radius=1.0,
                       wave="po+ptd", grid=(24, 36), N=64, refine=3, refine_model="none")
rows = summary_rows(ds)
for row in rows:
    print(" | ".join(row))
for line in verdict_lines(ds):
    print(line)

# %%
# The column "error: GO data" is the floor the scan itself sets on this coarse sphere without
# rim targets: GO's own data inverted with GO. The "GO cost" is what wave data add to it. The
# verdict's thresholds and the columns' definitions are in the check page of these docs.

# %%
# What the page shows
# -------------------
# ``check.html`` is self-contained; every number is also in ``check.nc``. Here: the ideal
# intensity's difference GO - wave at each frequency, which shrinks as the dish grows in
# wavelengths (the GO limit), and the panel gaps, dark lines in GO that the wave fills in.
fig, axes = plt.subplots(1, 2, figsize=(9, 3.6), layout="constrained")
for ax, i in zip(axes, range(ds.sizes["frequency"]), strict=True):
    diff = ds["intensity_ideal_go"][i] - ds["intensity_ideal_wave"][i]
    im = ax.pcolormesh(ds["phi"], ds["theta"], diff, shading="auto", cmap="RdBu_r")
    ax.set(title=f"GO - wave, ideal dish, {float(ds['frequency'][i]) / 1e9:g} GHz",
           xlabel="phi (rad)", ylabel="theta (rad)")
    fig.colorbar(im, ax=ax)
plt.show()
