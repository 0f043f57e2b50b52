"""Shared fixtures: small scenes and meshes reused across the tests, and the CLI runner."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".cache" / "warp"))
os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return ROOT


@pytest.fixture
def raysim_cli(capfd, monkeypatch):
    """Run the ``raysim`` command in this process: ``raysim_cli(*args) -> Result`` (exit
    status, stdout, stderr; see tests/cli.py), with wide columns."""
    from tests.cli import run_in_process

    monkeypatch.setenv("COLUMNS", "200")
    return lambda *args: run_in_process(capfd, *args)


@pytest.fixture(scope="session")
def paper_scene():
    from raysim.scene.scene import load_scene

    return load_scene(ROOT / "scenes" / "paper_go.toml")


@pytest.fixture(scope="session")
def panels_scene():
    from raysim.scene.scene import load_scene

    return load_scene(ROOT / "scenes" / "panels_go.toml")


@pytest.fixture(scope="session")
def paper_reflectors(paper_scene):
    """(ideal, deformed) reflectors of the paper scene at the default resolution."""
    from raysim.surface.mesh import reflectors_for

    return reflectors_for(paper_scene)
