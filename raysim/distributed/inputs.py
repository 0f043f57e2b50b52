"""The contents of the files a scene names (maps, panel tables, meshes), for fingerprints.

A resumable run (a dataset store, a distributed simulation's partial store) records a
fingerprint of what it computes. The scene's TOML holds only the *names* of its files, so
the fingerprint also takes the SHA-256 of each file's bytes: a resume after one of them was
edited is refused, naming the file, instead of mixing results of its two versions.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable
from pathlib import Path

_CHUNK = 1 << 20  # bytes read at a time: a mesh can be hundreds of MB


def file_sha256(path: Path) -> str:
    """SHA-256 (hex) of the bytes of the file ``path``."""
    sha = hashlib.sha256()
    with open(path, "rb") as handle:
        while block := handle.read(_CHUNK):
            sha.update(block)
    return sha.hexdigest()


def input_digests(files: Iterable[Path], base: str | os.PathLike[str]) -> dict[str, str]:
    """{name: SHA-256} of ``files`` (a scene's ``files``), each named relative to ``base``
    (the folder the scene's names resolve against), so that a project folder moved as a
    whole keeps its digests; sorted by name."""
    out = {}
    for path in files:
        name = os.path.relpath(Path(path).resolve(), Path(base).resolve())
        out[name] = file_sha256(Path(path))
    return dict(sorted(out.items()))


def changed_inputs(recorded: object, current: dict[str, str]) -> list[str]:
    """The names whose digests differ between ``recorded`` (a store's attribute, any JSON)
    and ``current``: changed, added or removed files, sorted."""
    theirs = recorded if isinstance(recorded, dict) else {}
    return sorted(k for k in set(theirs) | set(current) if theirs.get(k) != current.get(k))
