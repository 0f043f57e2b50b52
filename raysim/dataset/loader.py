"""Training batches from a dataset store: (input, target) numpy arrays, normalised.

A :class:`Loader` reads the samples of one split (``train``: ``split == 0``, ``validation``:
``split == 1``, or ``all``) whose ``status`` is done, from a store at a local path or any
fsspec URL (``file://``, ``memory://``, ``s3://`` with its fsspec package), and yields
batches ``(input, target)``:

- input, in one of three representations (:data:`REPRESENTATIONS`), of the clean
  ``intensity`` or, with ``source="measured"``, the ``intensity_measured`` of a store made
  with measurement effects:

  - ``intensity``: |E|^2 relative to the incident wave on the sphere, (B, n_theta, n_phi);
  - ``fa_sphere``: FA = I_ideal / I - 1 on the sphere (:func:`solver.equation.intensity_ratio_fa`),
    (B, n_theta, n_phi), with the stored ideal of the sample's frequency;
  - ``fa_aperture``: that FA resampled to the N x N aperture grid the solver uses
    (:func:`solver.resample.sphere_to_aperture` on a :class:`solver.aperture.ApertureGrid`:
    usable rows, missing points inpainted, the rim band extrapolated), (B, N, N), N the
    stored deformation map's by default;

- target: the deformation delta (m) on the store's aperture grid, (B, N, N).

With ``normalise`` (default) both are standardised, (x - mean) / std, by the statistics of
the *training* split (:class:`Statistics`: the mean and standard deviation over every finite
value of every done training sample), computed once per representation and source and kept
in the store's attributes (``normalisation``) when the store is writable, recomputed when the
training samples done or their checksums change, or the kept entry is malformed or edited (its
digest covers the samples' indices and checksums and its own values). NaN (outside the
aperture, beyond the rim image, a missing point) becomes ``fill`` after normalisation;
:attr:`Loader.target_mask` marks the aperture.

Nothing is returned unverified: opening checks the store's coordinates, split and attributes
against the checksums it recorded (:func:`raysim.dataset.integrity.check_static`), and every
sample read is checked against its ``checksum`` (its data arrays are read with it and hashed),
the ideal intensities against ``ideal_checksum``. A sample that fails raises
:class:`~raysim.dataset.integrity.CorruptSampleError` naming the store and the sample, which
``raysim dataset SPEC -o STORE --resume`` recomputes.
"""

from __future__ import annotations

import hashlib
import json
import math
import numbers
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from functools import cached_property
from typing import Any

import numpy as np
import zarr
from numpy.typing import NDArray

from raysim.dataset import integrity
from raysim.dataset.reading import SOURCES
from raysim.dataset.spec import DatasetError
from raysim.dataset.store import DONE, open_readonly, status
from raysim.maps.sphere import SphereGrid

REPRESENTATIONS = ("intensity", "fa_sphere", "fa_aperture")
SPLITS = {"train": 0, "validation": 1, "all": None}
ATTRIBUTE = "normalisation"


@dataclass(frozen=True)
class Statistics:
    """Mean and standard deviation (population, ddof 0) of the inputs and the targets over
    every finite value of the training samples ``samples`` (their count) fingerprinted by
    ``digest``; targets in m, inputs in the representation's unit."""

    input_mean: float
    input_std: float
    target_mean: float
    target_std: float
    samples: int
    digest: str


class _Moments:
    """Count, mean and sum of squared deviations, combined batch by batch (Chan et al.)."""

    def __init__(self) -> None:
        self.n, self.mean, self.m2 = 0, 0.0, 0.0

    def add(self, values: NDArray) -> None:
        v = np.asarray(values, dtype=np.float64)
        v = v[np.isfinite(v)]
        if not v.size:
            return
        n, mean = v.size, float(v.mean())
        m2 = float(np.sum((v - mean) ** 2))
        delta, total = mean - self.mean, self.n + n
        self.mean += delta * n / total
        self.m2 += m2 + delta * delta * self.n * n / total
        self.n = total

    @property
    def std(self) -> float:
        return math.sqrt(self.m2 / self.n) if self.n else math.nan


class Loader:
    """Batches of (input, target) arrays from a dataset store (see the module docstring).

    Parameters
    ----------
    store : local path or fsspec URL of the store.
    representation : one of :data:`REPRESENTATIONS`.
    source : ``clean`` (``intensity``) or ``measured`` (``intensity_measured``).
    split : ``train``, ``validation`` or ``all``.
    batch_size, drop_last : samples per batch; whether a last, shorter batch is dropped.
    shuffle, seed : a new order every epoch (``seed`` and the epoch's number) or index order.
    normalise : standardise by the training split's :class:`Statistics`.
    fill : the value NaN becomes (after normalisation).
    grid_n : N of the ``fa_aperture`` input (default: the stored deformation map's, so input
        and target share a grid; another N resamples the input only, the target stays on the
        store's grid).
    dtype : dtype of the arrays yielded.
    """

    def __init__(self, store: str, *, representation: str = "intensity", source: str = "clean",
                 split: str = "train", batch_size: int = 32, shuffle: bool = False, seed: int = 0,
                 drop_last: bool = False, normalise: bool = True, fill: float = 0.0,
                 grid_n: int | None = None, dtype: str = "float32") -> None:
        if representation not in REPRESENTATIONS:
            raise DatasetError(f"unknown representation {representation!r}: use one of "
                               f"{', '.join(REPRESENTATIONS)}")
        if split not in SPLITS:
            raise DatasetError(f"unknown split {split!r}: use one of {', '.join(SPLITS)}")
        if source not in SOURCES:
            raise DatasetError(f"unknown source {source!r}: use one of {', '.join(SOURCES)}")
        for name, value, lo in (("batch_size", batch_size, 1), ("seed", seed, 0),
                                ("grid_n", 8 if grid_n is None else grid_n, 8)):
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < lo:
                raise DatasetError(f"{name} must be an integer >= {lo}, got {value!r}")
        if not (isinstance(fill, numbers.Real) and not isinstance(fill, bool)):
            raise DatasetError(f"fill must be a number, got {fill!r}")
        try:
            if not np.issubdtype(np.dtype(dtype), np.floating):
                raise TypeError
        except TypeError:
            raise DatasetError(f"dtype must name a floating-point type (float32, float64), got "
                               f"{dtype!r}") from None
        self.store = str(store)
        self.group = open_readonly(self.store)
        integrity.check_static(self.group, self.store)
        if source == "measured" and self.group.attrs.get("measurement", "none") == "none":
            raise DatasetError(f"{self.store}: no {SOURCES[source]} (its spec has no [measurement] table)")
        self._arrays  # noqa: B018  (opened now: a missing or garbled array is one line, here)
        if SOURCES[source] not in self._arrays:
            raise integrity.CorruptStoreError(f"{self.store}: its array {SOURCES[source]!r} is not "
                                              f"listed; {integrity.resume_hint(self.store)}")
        self.representation, self.source, self.split = representation, source, split
        self.batch_size, self.shuffle, self.seed, self.drop_last = int(batch_size), shuffle, seed, drop_last
        self.normalise, self.fill, self.dtype = normalise, float(fill), np.dtype(dtype)
        self.grid_n = int(self.group["x"].shape[0] if grid_n is None else grid_n)
        self.epoch = 0
        self.indices = samples(self.group, split)

    # --- the store's geometry ---------------------------------------------------------------
    @cached_property
    def sphere(self) -> SphereGrid:
        a = self.group.attrs
        return SphereGrid(float(a["sphere_radius"]), self.group["theta"].shape[0], self.group["phi"].shape[0],
                          float(a["theta_min"]), float(a["theta_max"]), float(a["phi_min"]),
                          float(a["phi_max"]))

    @cached_property
    def _ideal(self) -> tuple[NDArray, NDArray, NDArray[np.bool_]]:
        """(frequencies in Hz, ideal intensities (n_f, n_theta, n_phi), which match their checksum)."""
        return integrity.read_ideals(self.group, self.store)

    @cached_property
    def _names(self) -> list[str]:
        """The per-sample data arrays a sample's checksum covers."""
        return integrity.data_names(self.group, self.store)

    @cached_property
    def _arrays(self) -> dict:
        """Those arrays, with ``status`` and ``checksum``, opened once."""
        return integrity.open_arrays(self.group, self.store, self._names)

    @cached_property
    def target_mask(self) -> NDArray[np.bool_]:
        """True at the aperture points (r < D/2) of the target grid, (N, N)."""
        x = np.asarray(self.group["x"][...])
        X, Y = np.meshgrid(x, x, indexing="xy")
        return np.hypot(X, Y) < 0.5 * float(self.group.attrs["diameter"])

    # --- raw arrays ---------------------------------------------------------------------------
    def raw(self, indices) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(inputs, targets) of the samples ``indices`` in the chosen representation,
        unnormalised, NaN kept, float64."""
        idx = np.asarray(indices, dtype=np.int64)
        order = np.argsort(idx, kind="stable")
        back = np.empty_like(order)
        back[order] = np.arange(len(idx))
        values = integrity.read_verified(self._arrays, self.store, idx[order], self._names,
                                         integrity.binding(self.group.attrs))
        intensity = np.asarray(values[SOURCES[self.source]], dtype=np.float64)[back]
        target = np.asarray(values["deformation"], dtype=np.float64)[back]
        if self.representation == "intensity":
            return intensity, target
        f = np.asarray(values["frequency_hz"])[back]
        fa = [self._fa(i, integrity.ideal_of(self.store, *self._ideal, fi))
              for i, fi in zip(intensity, f, strict=True)]
        return np.stack(fa), target

    def _fa(self, intensity: NDArray, ideal: NDArray) -> NDArray[np.float64]:
        from solver.equation import intensity_ratio_fa

        fa = intensity_ratio_fa(intensity, ideal)
        if self.representation == "fa_sphere":
            return fa
        from solver.aperture import ApertureGrid
        from solver.resample import sphere_to_aperture

        a = self.group.attrs
        F, D = float(a["focal_length"]), float(a["diameter"])
        return sphere_to_aperture(fa, self.sphere, ApertureGrid(D, self.grid_n), F, D)[0]

    # --- statistics -----------------------------------------------------------------------------
    @property
    def key(self) -> str:
        """The statistics' key in the store's ``normalisation`` attribute."""
        n = f"/{self.grid_n}" if self.representation == "fa_aperture" else ""
        return f"{self.representation}/{self.source}{n}"

    @cached_property
    def statistics(self) -> Statistics:
        """The training split's statistics: from the store's attributes when the entry is
        whole and its digest matches the training samples done now (their indices and
        checksums) and its own values, else computed (once) and written there (when the store
        is writable)."""
        train = samples(self.group, "train")
        sums = self._checksums(train)
        kept = _kept_statistics(self.group.attrs.get(ATTRIBUTE), self.key, train, sums)
        if kept is not None:
            return kept
        if not len(train):
            raise DatasetError(f"{self.store}: no training sample is done: no statistics to normalise by")
        inputs, targets = _Moments(), _Moments()
        for start in range(0, len(train), 64):
            x, y = self.raw(train[start:start + 64])
            inputs.add(x)
            targets.add(y)
        values = (inputs.mean, inputs.std, targets.mean, targets.std, len(train))
        stats = Statistics(*values, _statistics_digest(train, sums, values))
        try:
            writable = zarr.open_group(self.store, mode="r+")
            current = dict(writable.attrs.get(ATTRIBUTE, {}))
            current[self.key] = asdict(stats)
            writable.attrs[ATTRIBUTE] = current
        except Exception:  # a read-only store: the statistics live in this loader only
            pass
        return stats

    def _checksums(self, indices: NDArray[np.int64]) -> list[str]:
        """The stored checksums of the samples ``indices`` (what their statistics are keyed on:
        other data under the same indices give other statistics)."""
        try:
            stored = np.asarray(self.group["checksum"][...])
        except Exception as exc:
            raise integrity.CorruptStoreError(f"{self.store}: its array 'checksum' cannot be read "
                                              f"({type(exc).__name__}); {integrity.resume_hint(self.store)}"
                                              ) from exc
        return [str(stored[i]) for i in indices.tolist()]

    # --- batches -------------------------------------------------------------------------------
    def _finish(self, x: NDArray, y: NDArray) -> tuple[NDArray, NDArray]:
        if self.normalise:
            s = self.statistics
            x = (x - s.input_mean) / s.input_std
            y = (y - s.target_mean) / s.target_std
        x = np.where(np.isfinite(x), x, self.fill).astype(self.dtype)
        y = np.where(np.isfinite(y), y, self.fill).astype(self.dtype)
        return x, y

    def sample(self, position: int) -> tuple[NDArray, NDArray]:
        """(input, target) of the ``position``-th sample of the split (no batch axis)."""
        x, y = self._finish(*self.raw([self.indices[position]]))
        return x[0], y[0]

    def order(self, epoch: int) -> NDArray[np.int64]:
        """The split's sample indices in the order of ``epoch``."""
        if not self.shuffle:
            return self.indices
        rng = np.random.default_rng([self.seed, epoch])
        return self.indices[rng.permutation(len(self.indices))]

    def __len__(self) -> int:
        n, b = len(self.indices), self.batch_size
        return n // b if self.drop_last else -(-n // b)

    def __iter__(self) -> Iterator[tuple[NDArray, NDArray]]:
        """One epoch of batches; each pass over the loader is the next epoch."""
        order = self.order(self.epoch)
        self.epoch += 1
        for k in range(len(self)):
            yield self._finish(*self.raw(order[k * self.batch_size:(k + 1) * self.batch_size]))


_FIELDS = ("input_mean", "input_std", "target_mean", "target_std", "samples", "digest")


def _statistics_digest(train: NDArray[np.int64], sums: list[str], values: tuple) -> str:
    """SHA-256 (hex, 16 digits) of the training samples (indices and checksums) and of the
    statistics' values: an entry edited, or left from other samples or data, no longer matches."""
    text = json.dumps({"samples": train.astype(np.int64).tolist(), "checksums": sums,
                       "values": [float(v) for v in values[:4]] + [int(values[4])]})
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _kept_statistics(attribute: Any, key: str, train: NDArray[np.int64],
                     sums: list[str]) -> Statistics | None:
    """The statistics kept under ``key`` in the ``normalisation`` attribute when they are
    current; None (compute them again) when absent, malformed or not current."""
    entry = attribute.get(key) if isinstance(attribute, dict) else None
    if not isinstance(entry, dict) or set(entry) != set(_FIELDS):
        return None
    numbers_ok = all(isinstance(entry[k], numbers.Real) and not isinstance(entry[k], bool)
                     for k in _FIELDS[:4])
    if not numbers_ok or not isinstance(entry["samples"], int) or not isinstance(entry["digest"], str):
        return None
    values = tuple(entry[k] for k in _FIELDS[:5])
    if entry["digest"] != _statistics_digest(train, sums, values):
        return None
    return Statistics(*(float(v) for v in values[:4]), int(values[4]), entry["digest"])


def samples(group: zarr.Group, split: str) -> NDArray[np.int64]:
    """Indices of the done samples of ``split`` (``train``, ``validation`` or ``all``); a torn
    status marker counts as not done (:func:`raysim.dataset.store.status`; the decoder's
    RuntimeError reached the user)."""
    done = status(group) == DONE
    which = SPLITS[split]
    if which is not None:
        done &= np.asarray(group["split"][...]) == which
    return np.flatnonzero(done)
