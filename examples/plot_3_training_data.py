"""
Training data for a learned inverse
===================================

``raysim dataset`` simulates random but physical surface errors in bulk (on Dask, each sample
written by its worker into a Zarr store, each regenerable alone from its seed), and
:class:`raysim.dataset.loader.Loader` yields normalised ``(input, target)`` batches from it.
Here: a store of 8 samples of the shipped ``dataset_demo`` spec on a coarser sphere, the
loader, and a few training steps of a tiny model: with PyTorch where it is installed
(``pip install 'raysim[torch]'``), skipped with a note where it is not; a linear model in
NumPy runs in either case. The command line equivalent of the first step is
``raysim dataset dataset_demo -o out/dataset_demo.zarr --workers 1``.
"""

# %%
# A small store
# -------------
import importlib.util
import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from raysim.dataset.loader import Loader
from raysim.files import example

work = Path(tempfile.mkdtemp(prefix="raysim-tutorial-"))
spec = work / "spec.toml"
spec.write_text(example("dataset_demo").read_text()
                .replace("n_theta = 30", "n_theta = 20").replace("n_phi = 120", "n_phi = 40"))
store = work / "demo.zarr"
# the command in its own process: Dask starts its worker processes from a clean interpreter
done = subprocess.run([sys.executable, "-m", "raysim.cli", "dataset", str(spec), "-o", str(store),
                       "--workers", "1"], capture_output=True, text=True, check=True)
print(done.stdout.strip())

# %%
# The loader
# ----------
# ``fa_aperture``: the scan's FA resampled onto the solver's aperture grid, the same grid as
# the target deformation map, each standardised by the training split's statistics.
train = Loader(str(store), representation="fa_aperture", split="train", batch_size=3, shuffle=True)
valid = Loader(str(store), representation="fa_aperture", split="validation", batch_size=8)
x, y = next(iter(train))
print("one batch:", x.shape, x.dtype, "->", y.shape)

fig, axes = plt.subplots(1, 2, figsize=(8, 3.6), layout="constrained")
for ax, image, title in zip(axes, (x[0], y[0]), ("input: FA on the aperture grid",
                                                  "target: deformation"), strict=True):
    im = ax.imshow(image, origin="lower", cmap="RdBu_r")
    ax.set_title(title)
    fig.colorbar(im, ax=ax)
plt.show()

# %%
# A tiny linear model in NumPy
# ----------------------------
# Normalised gradient descent on a per-pixel linear map target = a * input + b: only a check
# that the data flow end to end, not an inverse. The deformation is a Poisson solve away from
# FA, so each pixel's target depends on the FA of the whole aperture, which a per-pixel map
# cannot see: on six training samples its validation error wanders about that of predicting
# the training mean (0 after standardisation). The step is divided by each pixel's input power,
# so it cannot diverge. ``benchmarks/bench_baseline.py`` gives the errors of the project's own
# inversion on a store's validation split: what a learned inverse has to beat.
mean_only = np.mean([float(np.mean(yv**2)) for _, yv in valid])
print(f"predicting the training mean: validation MSE {mean_only:.3f} (0 is perfect)")
a, b, rate = np.zeros(x.shape[1:]), np.zeros(x.shape[1:]), 0.5
for epoch in range(5):
    for xb, yb in train:
        residual = a * xb + b - yb
        a -= rate * (residual * xb).mean(axis=0) / (1.0 + (xb**2).mean(axis=0))
        b -= rate * residual.mean(axis=0)
    losses = [float(np.mean((a * xv + b - yv) ** 2)) for xv, yv in valid]
    print(f"epoch {epoch}: validation MSE {np.mean(losses):.3f}")

# %%
# A few steps of a tiny PyTorch model
# -----------------------------------
if importlib.util.find_spec("torch") is None:
    print("PyTorch is not installed here: skipping (pip install 'raysim[torch]')")
else:
    import torch

    from raysim.dataset.torch_data import TorchDataset

    data = TorchDataset(str(store), representation="fa_aperture", split="train")
    batches = torch.utils.data.DataLoader(data, batch_size=3, shuffle=True)
    model = torch.nn.Sequential(torch.nn.Conv2d(1, 4, 3, padding=1), torch.nn.ReLU(),
                                torch.nn.Conv2d(4, 1, 3, padding=1))
    optimiser = torch.optim.Adam(model.parameters(), lr=1e-2)
    for step, (xb, yb) in zip(range(6), batches, strict=False):
        loss = torch.nn.functional.mse_loss(model(xb[:, None])[:, 0], yb)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        print(f"step {step}: training MSE {loss.item():.3f}")
