"""Data of the Gauss-Newton benchmark: FieldMaps made with a finer model than the inversion's.

The inversion's PO model (:class:`solver.forward.WaveForward`) integrates on 5 m faces with
1.5 samples per wavelength and the rim's PTD fringe field at 4 points per wavelength. The
data here use 4 m faces (another triangulation), 3 samples per wavelength (twice) and 8 edge
points per wavelength, so the model never repeats the data's computation (no inverse crime).
Above 0.3 GHz the data's sums run on the fast radiator at a tolerance of 1e-9 (``DATA_TOL``;
the direct sum of 3 samples per wavelength would take hours at 1 GHz): a thousand times tighter
than the model's, and on other elements, so the data still come from a finer model. Each
FieldMap is cached under ``out/gauss_newton/`` (ignored by git) and reused.

Deformations: the paper's Eq. 8 and a second one that is not the paper's: a gravity-like rim
astigmatism A (r/a)^p cos(2 (phi - phi0)) plus actuator-scale Gaussian bumps, drawn with the
laws of ``scenes/dataset_demo.toml`` (:mod:`raysim.dataset.models`) from a fixed seed, with 64
rim targets on r = D/2.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import xarray as xr

from raysim.maps.fieldmap import fieldmap, load, save
from raysim.maps.sphere import SphereGrid

D, F, R = 110.0, 33.0, 10.0
DATA_FACE_M = 4.0
DATA_SPW = 3.0
DATA_EDGE_PPW = 8.0
DATA_TOL = 1e-9  # the fast radiator's tolerance for the data's sums, above DIRECT_UPTO_HZ
DIRECT_UPTO_HZ = 0.3e9  # the data's sums by the direct sum up to here (the cached 0.1, 0.3 GHz data)
NOISE_DB = 0.01
SECOND_SEED = 20240917
OUT = Path(__file__).resolve().parent.parent / "out" / "gauss_newton"


def paper_deformation():
    from raysim.surface.deformation import PaperDeformation

    return PaperDeformation(D, F, 1.0)


def second_deformation():
    """Rim astigmatism + bumps drawn with the dataset spec's laws (seed SECOND_SEED)."""
    from raysim.dataset.distributions import Distribution
    from raysim.dataset.models import ApertureGrid, GravityAstigmatism, RandomBumps
    from raysim.surface.deformation import Sum

    grid = ApertureGrid(D, 128)
    rng = np.random.default_rng(SECOND_SEED)
    um = 1e-6
    gravity = GravityAstigmatism("gravity", Distribution("uniform", 40 * um, 150 * um), 1.0,
                                 exponent=Distribution("uniform", 2.5, 4.0),
                                 angle=Distribution("fixed", np.pi / 2, np.pi / 2))
    bumps = RandomBumps("bumps", Distribution("loguniform", 10 * um, 60 * um), 1.0,
                        count=Distribution("integers", 2, 6),
                        sigma=Distribution("uniform", 1.5, 4.0))
    parts = [gravity.draw(rng, grid)[0], bumps.draw(rng, grid)[0]]
    return Sum(tuple(parts))


def rim_targets(deformation, n: int = 64):
    """``n`` rim targets on r = D/2 (equal azimuth steps, half a step off x) with the truth."""
    from solver.boundary import RimTargets

    phi = (np.arange(n) + 0.5) * 2.0 * np.pi / n
    x, y = 0.5 * D * np.cos(phi), 0.5 * D * np.sin(phi)
    return RimTargets(x, y, np.asarray(deformation(x, y), dtype=np.float64), "64 rim targets")


DEFORMATIONS = {"paper": paper_deformation, "second": second_deformation}


def _fine_field(reflector, sphere, frequency_hz):
    from raysim.optics import po, ptd

    wave = po.Illumination.plane_wave(frequency_hz, (0.0, 0.0, -1.0), (1.0, 0.0, 0.0))
    how = {} if frequency_hz <= DIRECT_UPTO_HZ else {"radiator": "fast", "tol": DATA_TOL}
    E = po.sphere_field(reflector, sphere, wave, DATA_SPW, **how).E
    E = E + ptd.sphere_edge_field(reflector, sphere, wave, "rim", DATA_EDGE_PPW, **how).E
    return np.sum(np.abs(E) ** 2, axis=-1)


def fine_fieldmap(frequency_hz: float, name: str, n_theta: int = 90, n_phi: int = 360,
                  log=print) -> xr.Dataset:
    """The finer model's PO + PTD FieldMap of deformation ``name`` (cached, noise-free)."""
    from raysim.surface.mesh import paraboloid

    OUT.mkdir(parents=True, exist_ok=True)
    tag = f"{frequency_hz / 1e9:g}GHz_{n_theta}x{n_phi}"
    path = OUT / f"fine_{name}_{tag}.nc"
    if path.is_file():
        return load(path)
    sphere = SphereGrid(R, n_theta, n_phi)
    ideal_path = OUT / f"fine_ideal_{tag}.npy"
    dish = paraboloid(D, F, DATA_FACE_M)
    start = time.perf_counter()
    if ideal_path.is_file():
        ideal = np.load(ideal_path)
    else:
        ideal = _fine_field(dish, sphere, frequency_hz)
        np.save(ideal_path, ideal)
        log(f"{tag}: fine ideal field in {time.perf_counter() - start:.0f} s")
    start = time.perf_counter()
    deformed = _fine_field(dish.deformed(DEFORMATIONS[name]()), sphere, frequency_hz)
    log(f"{tag}: fine {name} field in {time.perf_counter() - start:.0f} s")
    ds = fieldmap(sphere, deformed, ideal, focal_length=F, diameter=D, frequency_hz=frequency_hz,
                  method="po+ptd", sampling="centre",
                  attrs={"deformation": name, "data_face_m": DATA_FACE_M,
                         "data_radiator": "direct" if frequency_hz <= DIRECT_UPTO_HZ
                         else f"fast {DATA_TOL:g}",
                         "data_samples_per_wavelength": DATA_SPW,
                         "data_edge_points_per_wavelength": DATA_EDGE_PPW})
    save(ds, path)
    return ds


def with_noise(ds: xr.Dataset, noise_db: float = NOISE_DB, seed: int = 1) -> xr.Dataset:
    """``ds`` with Gaussian noise of ``noise_db`` dB (standard deviation) on every sample."""
    rng = np.random.default_rng(seed)
    out = ds.copy(deep=True)
    factor = 10.0 ** (noise_db * rng.standard_normal(ds["intensity"].shape) / 10.0)
    out["intensity"] = ds["intensity"] * factor
    out.attrs["noise_db"] = noise_db
    return out


if __name__ == "__main__":
    import sys

    for arg in sys.argv[1:] or ["0.1e9", "0.3e9"]:
        f = float(arg)
        for name in DEFORMATIONS:
            fine_fieldmap(f, name)
