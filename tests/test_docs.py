"""The documentation stays inside the repository and in step with the layer contracts."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def anchors(page: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces to hyphens."""
    out = set()
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            text = line.lstrip("#").strip().lower()
            out.add(re.sub(r"\s", "-", re.sub(r"[^\w\s-]", "", text)))
    return out


def test_every_link_resolves_to_a_file_of_the_repository():
    assert len(PAGES) >= 7
    for page in PAGES:
        for target in LINK.findall(page.read_text(encoding="utf-8")):
            assert "://" not in target, f"{page.name}: external link {target}"
            path, _, anchor = target.partition("#")
            resolved = (page.parent / path).resolve() if path else page
            assert resolved.is_relative_to(ROOT), f"{page.name}: {target} leaves the repository"
            assert resolved.exists(), f"{page.name}: {target} does not exist"
            if anchor and resolved.suffix == ".md":
                assert anchor in anchors(resolved), f"{page.name}: no heading for #{anchor}"


def test_the_architecture_page_names_every_layer_of_the_contract():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    contract = config["tool"]["importlinter"]["contracts"][0]
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    for layer in contract["layers"]:
        for unit in layer.split("|"):
            assert unit.strip() in text, unit
    for leaf in config["tool"]["importlinter"]["contracts"][1]["source_modules"]:
        assert leaf in text, leaf
