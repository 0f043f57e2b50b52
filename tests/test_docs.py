"""The documentation stays inside the repository and in step with the layer contracts."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# every Markdown page: the README and the site's sources under docs/ (how-to and reference
# pages in their subfolders), not the build's output
BUILT = ("_build", "tutorials", "generated")
PAGES = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").rglob("*.md")
                                     if not set(p.relative_to(ROOT / "docs").parts) & set(BUILT))]
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
    assert len(PAGES) >= 18
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


def command_names() -> list[str]:
    """Every command of the ``raysim`` CLI as it is typed: ``simulate``, ``rig park``, ..."""
    import typer.main

    from raysim.cli import app

    group = typer.main.get_command(app)
    names = []
    for name, command in group.commands.items():
        subcommands = getattr(command, "commands", None)
        names += [f"{name} {sub}" for sub in subcommands] if subcommands else [name]
    return names


def test_every_command_is_documented_with_an_example():
    text = "\n".join(page.read_text(encoding="utf-8") for page in PAGES)
    names = command_names()
    assert {"simulate", "invert", "check", "budget", "paper", "rig park"} <= set(names)
    for name in names:
        assert f"raysim {name} " in text, f"no example of 'raysim {name}' in README.md or docs/"
