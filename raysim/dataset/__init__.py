"""Training and validation data in bulk: random physical surface errors, simulated on Dask,
written into one Zarr store (``raysim dataset SPEC -o STORE.zarr``).

Modules, in the order data flows through them:

- ``distributions``: the laws a spec's random parameters follow.
- ``models``: random surface-error models (Zernike spectra, actuator-scale bumps, panel
  pistons and tilts, gravity-like rim astigmatism), each scaled to a drawn RMS.
- ``toml_text``: TOML text of a parsed table (an inline scene back into a scene file).
- ``spec``: spec TOML -> :class:`DatasetSpec`, and its fingerprint.
- ``sampling``: per-sample seeds, the train/validation split, one sample's surface.
- ``store_layout``, ``store``: the Zarr layout; creation, checks, per-sample writes.
- ``integrity``: what a resume checks besides the samples, and the readers' verified reads.
- ``worker``: what runs in a Dask worker (set-up plugin, the sample and ideal tasks).
- ``run``: the client (:func:`generate`): cluster, tasks, progress, resume.
- ``effects``: measurement effects (the spec's ``[measurement]`` table), drawn per sample.
- ``memo``, ``engine``: one sample's physics, with what the samples share kept per process.
- ``reading``: the store as xarray, one sample as a FieldMap, one sample regenerated alone.
- ``loader``: normalised (input, target) training batches; ``torch_data`` and ``jax_data``
  wrap it for PyTorch and JAX (optional extras).
"""

from raysim.dataset.integrity import CorruptSampleError, CorruptStoreError
from raysim.dataset.loader import Loader
from raysim.dataset.reading import open_dataset, sample_fieldmap, sample_intensity, sample_measured
from raysim.dataset.run import RunReport, generate
from raysim.dataset.sampling import SampleDraw, draw_sample, sample_seed, validation_mask
from raysim.dataset.spec import DatasetError, DatasetSpec, load_spec, parse_spec

__all__ = [
    "CorruptSampleError",
    "CorruptStoreError",
    "DatasetError",
    "DatasetSpec",
    "Loader",
    "RunReport",
    "SampleDraw",
    "draw_sample",
    "generate",
    "load_spec",
    "open_dataset",
    "parse_spec",
    "sample_fieldmap",
    "sample_intensity",
    "sample_measured",
    "sample_seed",
    "validation_mask",
]
