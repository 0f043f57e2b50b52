"""The partial store of a distributed simulation: blocks of sphere points kept as they finish.

``OUTPUT.partial.zarr`` beside the output, a local folder:

- a Zarr (format 3) group whose attributes hold the format, the run's fingerprint and what it
  is made of (to say what differs when a resume is refused), the grid's point count and the
  block size; one float64 array per part of the engine, ``(n_points, *tail)``, one block per
  chunk, so no two blocks share a chunk (a chunk torn by a kill fails its block's checksum);
- ``context.json``: the context's attributes (the same from every worker) and their SHA-256
  with the run's fingerprint, written before any block's marker;
- ``blocks/NNNNNN.json``: the completion marker of each block, written last (atomically, by
  rename) with the block's figures, the digest of the elements that made it, ``sha256`` (per
  part, the SHA-256 of the run's fingerprint, the block's index, the part's name and its
  float64 values in C order, as written: a block moved to another index or brought from
  another run's store fails it) and ``count``, how many times the block was computed and
  written (1; more only if two workers ran it at once, which the FieldMap records as
  ``blocks_computed_twice``).

A block whose marker exists is not computed again: a killed client or worker resumes from
the markers, and a worker handed a block already marked (Dask rerunning a task whose result
was lost with its worker) skips it. A resume first re-reads every marked block
(:meth:`PartialStore.verify`): one that does not decode, has the wrong shape, or whose values
do not match its checksum (a chunk file removed reads as NaN) loses its marker and its chunks
and is computed again (:meth:`PartialStore.reset`); a ``context.json`` that does not match its
checksum is made again with one block. Arrays whose metadata (shape, chunks, type) differ from
the store's layout are refused when the store opens.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import uuid
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from raysim.distributed.cluster import ClusterError
from raysim.files import atomic_path

FORMAT = 2  # 2: checksums bound to the run, the block and the part; context checksummed
SUFFIX = ".partial.zarr"


def partial_path(output: str | os.PathLike[str]) -> Path:
    """Where the partial store of ``output`` lives: ``OUTPUT.partial.zarr`` beside it."""
    out = Path(output).expanduser().resolve()
    return out.with_name(out.name + SUFFIX)


class PartialStore:
    """An open partial store (see the module docs)."""

    def __init__(self, path: Path, group: Any) -> None:
        self.path = Path(path)
        self.group = group
        attrs = group.attrs
        self.fingerprint = str(attrs["fingerprint"])
        self.n_points = int(attrs["n_points"])
        self.block_size = int(attrs["block_size"])
        self.parts: dict[str, tuple[int, ...]] = {k: tuple(v) for k, v in dict(attrs["parts"]).items()}
        self._arrays: dict[str, Any] = {}

    # --- making and opening ------------------------------------------------------------------
    @classmethod
    def create(cls, path: Path, fingerprint: str, description: dict[str, str],
               parts: dict[str, tuple[int, ...]], n_points: int, block_size: int) -> PartialStore:
        """A new store at ``path`` (which must not exist), built aside and renamed into place."""
        import zarr

        from raysim.files import remove_stale, writer_prefix

        path = Path(path)
        remove_stale(path)  # what a run killed while creating it left, once that run is gone
        scratch = path.parent / f"{writer_prefix(path)}{uuid.uuid4().hex[:8]}.tmp"
        attrs = {"raysim_partial_format": FORMAT, "fingerprint": fingerprint,
                 "fingerprint_parts": description, "n_points": int(n_points),
                 "block_size": int(block_size), "parts": {k: list(v) for k, v in parts.items()},
                 "created": datetime.now(UTC).isoformat(timespec="seconds")}
        try:
            group = zarr.open_group(str(scratch), mode="w-", attributes=attrs)
            for name, tail in parts.items():
                group.create_array(name, shape=(n_points, *tail), chunks=(block_size, *tail),
                                   dtype="float64", fill_value=np.nan)
            (scratch / "blocks").mkdir()
            os.rename(scratch, path)  # fails if the target appeared meanwhile
        except OSError as exc:
            raise ClusterError(f"{path}: cannot create the partial store ({exc.strerror or exc})") from exc
        finally:
            shutil.rmtree(scratch, ignore_errors=True)
        return cls.open(path, fingerprint)

    @classmethod
    def open(cls, path: Path, fingerprint: str | None = None,
             description: dict[str, str] | None = None) -> PartialStore:
        """Open an existing store; with ``fingerprint``, refuse one another run made."""
        import zarr

        try:
            group = zarr.open_group(str(path), mode="r+")
            made = group.attrs.get("raysim_partial_format")
        except (FileNotFoundError, ValueError, KeyError, OSError) as exc:
            raise ClusterError(f"{path}: not a raysim partial store ({type(exc).__name__}); "
                               "delete it to start again") from exc
        if made != FORMAT:
            raise ClusterError(f"{path}: not a raysim partial store of format {FORMAT}; delete it "
                               "to start again")
        try:
            store = cls(path, group)
            for name in store.parts:
                store._array(name)
        except (KeyError, TypeError, ValueError, OSError) as exc:
            raise ClusterError(f"{path}: its metadata cannot be read ({type(exc).__name__}: {exc}); "
                               "delete it to start again") from exc
        store._check_layout()
        if fingerprint is not None and store.fingerprint != fingerprint:
            theirs = dict(group.attrs.get("fingerprint_parts", {}))
            ours = description or {}
            differ = sorted(k for k in set(theirs) | set(ours) if theirs.get(k) != ours.get(k))
            raise ClusterError(f"{path} holds blocks of another run (it differs in: "
                               f"{', '.join(differ) or 'its fingerprint'}): delete it to start again")
        return store

    def _check_layout(self) -> None:
        """Refuse arrays whose shape, chunks or type are not the layout's: values written
        through edited metadata would come back as other numbers."""
        for name, tail in self.parts.items():
            array = self._array(name)
            layout = ((self.n_points, *tail), (self.block_size, *tail), np.dtype(np.float64))
            if (tuple(array.shape), tuple(array.chunks), np.dtype(array.dtype)) != layout:
                raise ClusterError(
                    f"{self.path}: its array {name!r} has shape {tuple(array.shape)}, chunks "
                    f"{tuple(array.chunks)} and type {array.dtype}, not the store's "
                    f"{layout[0]}, {layout[1]} and float64: delete it to start again")

    # --- blocks ------------------------------------------------------------------------------
    @property
    def n_blocks(self) -> int:
        return -(-self.n_points // self.block_size)

    def bounds(self, index: int) -> tuple[int, int]:
        """Points lo..hi-1 of block ``index``."""
        lo = index * self.block_size
        return lo, min(lo + self.block_size, self.n_points)

    def _marker(self, index: int) -> Path:
        return self.path / "blocks" / f"{index:06d}.json"

    def marker(self, index: int) -> dict | None:
        """Block ``index``'s completion record, or None while it is not done."""
        try:
            return json.loads(self._marker(index).read_text())
        except (FileNotFoundError, ValueError):
            return None

    def markers(self) -> dict[int, dict]:
        """Every completed block's record, by index."""
        out = {}
        for entry in (self.path / "blocks").glob("*.json"):
            with contextlib.suppress(ValueError):
                out[int(entry.stem)] = json.loads(entry.read_text())
        return out

    def exists(self) -> bool:
        """False once the store was removed (a late writer must not recreate it)."""
        return (self.path / "zarr.json").is_file()

    def write(self, index: int, arrays: dict[str, np.ndarray], record: dict) -> int:
        """Write block ``index``'s arrays, then its marker; return its computation count."""
        lo, hi = self.bounds(index)
        sums = {}
        for name, tail in self.parts.items():
            values = np.asarray(arrays[name], dtype=np.float64)
            if values.shape != (hi - lo, *tail):
                raise ClusterError(f"block {index}: part {name!r} has shape {values.shape}, "
                                   f"expected {(hi - lo, *tail)}")
            self._array(name)[lo:hi] = values
            sums[name] = self._checksum(index, name, values)
        previous = self.marker(index)
        count = 1 + (int(previous["count"]) if previous else 0)
        _write_json(self._marker(index), {**record, "index": index, "count": count, "sha256": sums})
        return count

    def intact(self, index: int, record: dict) -> bool:
        """Whether block ``index``'s stored values decode, have their shape and match the
        checksums of its marker ``record`` (a marker without them cannot be trusted)."""
        sums = record.get("sha256")
        if not isinstance(sums, dict) or set(sums) != set(self.parts):
            return False
        lo, hi = self.bounds(index)
        for name, tail in self.parts.items():
            try:
                values = np.asarray(self._array(name)[lo:hi])
            except Exception:  # a truncated or garbled chunk: its codec's error
                return False
            if values.shape != (hi - lo, *tail) or self._checksum(index, name, values) != sums[name]:
                return False
        return True

    def _checksum(self, index: int, name: str, values: np.ndarray) -> str:
        return checksum(values, f"{self.fingerprint}/{index}/{name}")

    def verify(self) -> list[int]:
        """The marked blocks that fail :meth:`intact` (and markers outside the grid), sorted."""
        return sorted(i for i, record in self.markers().items()
                      if not 0 <= i < self.n_blocks or not self.intact(i, record))

    def reset(self, index: int) -> None:
        """Make block ``index`` pending again: its marker first, then its chunks (written as
        the fill value, which removes them)."""
        self._marker(index).unlink(missing_ok=True)
        if not 0 <= index < self.n_blocks:
            return
        lo, hi = self.bounds(index)
        for name, tail in self.parts.items():
            self._array(name)[lo:hi] = np.full((hi - lo, *tail), np.nan)

    def _array(self, name: str) -> Any:
        if name not in self._arrays:
            self._arrays[name] = self.group[name]
        return self._arrays[name]

    def read(self) -> dict[str, np.ndarray]:
        """Every part over the whole grid (NaN where a block is missing)."""
        return {name: np.asarray(self._array(name)[...]) for name in self.parts}

    # --- the context's attributes ------------------------------------------------------------
    def context(self) -> dict | None:
        """The context's attributes; None while none are recorded or when they do not match
        their checksum."""
        try:
            record = json.loads((self.path / "context.json").read_text())
            attrs, sha = record["attrs"], record["sha256"]
        except (FileNotFoundError, ValueError, KeyError, TypeError):
            return None
        return attrs if isinstance(attrs, dict) and sha == self._context_sum(attrs) else None

    def set_context(self, attrs: dict) -> None:
        """Record the context's attributes once (every writer's are the same)."""
        if not (self.path / "context.json").is_file():
            _write_json(self.path / "context.json",
                        {"attrs": attrs, "sha256": self._context_sum(attrs)})

    def _context_sum(self, attrs: dict) -> str:
        text = json.dumps(attrs, sort_keys=True, allow_nan=True, default=_plain)
        return hashlib.sha256(f"{self.fingerprint}/context/{text}".encode()).hexdigest()

    def remove(self) -> None:
        shutil.rmtree(self.path, ignore_errors=True)


def checksum(values: np.ndarray, label: str = "") -> str:
    """SHA-256 (hex) of ``label`` (UTF-8, then a NUL) and ``values`` as float64 in C order:
    what a marker records per part, labelled with the run, the block and the part."""
    digest = hashlib.sha256(label.encode() + b"\0")
    digest.update(np.ascontiguousarray(values, dtype=np.float64).tobytes())
    return digest.hexdigest()


def _write_json(path: Path, value: dict) -> None:
    """Write ``value`` to ``path`` atomically (a reader sees the old file or the new one)."""
    with atomic_path(path, clean=False) as tmp:
        tmp.write_text(json.dumps(value, sort_keys=True, allow_nan=True, default=_plain))


def _plain(value: Any) -> Any:
    """numpy scalars as Python numbers for JSON."""
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")
