"""
Pictures: headless renders of a FieldMap and a SurfaceMap
=========================================================

:func:`raysim.render.api.render_image` draws either data contract as an RGB array, off-screen
(VTK through EGL for the 3-D views, matplotlib for maps and cuts), so it runs on a server
with no display; ``raysim render FILE -o OUT.png --kind 3d|map|cut`` writes the same pictures
to PNG files.
"""

# %%
# A FieldMap and its SurfaceMap
# -----------------------------
# The paper's dish with Eq. 8's deformation, on a coarse mesh and sphere (seconds).
import matplotlib.pyplot as plt

import raysim
import solver
from raysim.render.api import render_image

scene = raysim.load_scene("paper_go").with_overrides(n_theta=45, n_phi=90)
field = raysim.simulate(scene, method="go")
surface = solver.invert(field, N=64, refine_iterations=1)
print(f"RRMS of the recovered map against Eq. 8: {100 * surface.attrs['rrms']:.2f} %")

# %%
# The FieldMap: FA on the probe sphere in 3-D, and as a (theta, phi) map
# ----------------------------------------------------------------------
# FA is the relative intensity change the deformation makes (ideal over deformed, minus 1).
def show(image, title):
    """An RGB array as a figure of its own, without axes."""
    _, ax = plt.subplots(figsize=(8, 8 * image.shape[0] / image.shape[1]), layout="constrained")
    ax.imshow(image)
    ax.set_axis_off()
    ax.set_title(title)


for kind in ("3d", "map", "cut"):
    image = render_image(field, kind=kind, size="800x600")
    show(image, f"FieldMap, --kind {kind}")
    print(f"FieldMap, {kind}: {image.shape[1]} x {image.shape[0]} pixels")
plt.show()

# %%
# The SurfaceMap: the recovered deformation beside the truth and the error
# ------------------------------------------------------------------------
show(render_image(surface, kind="map", size="1800x750"), "SurfaceMap, --kind map")
show(render_image(surface, kind="3d", size="1800x750"), "SurfaceMap, --kind 3d")
plt.show()
