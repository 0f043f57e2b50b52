"""Constraints files for pip from pyproject.toml (standard library only).

    python scripts/constraints.py lowest OUT   # every direct dependency pinned to its lower bound

The lower bounds in pyproject.toml are what library users get promised; ``RAYSIM_DEPS=lowest``
(make, .ci/run) installs exactly them, so a wrong bound fails the suite. The lock file
``constraints.txt`` (today's fresh resolve) is written by ``make lock``, not by this script.
"""

from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BOUND = re.compile(r"^\s*([A-Za-z0-9_.\-]+)\s*(\[[^\]]*\])?\s*>=\s*([^,;\s]+)")


def lowest() -> list[str]:
    """``name==lower`` for every direct dependency (runtime, test and docs extras)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    lines = []
    for requirement in [*project["dependencies"], *project["optional-dependencies"]["test"],
                        *project["optional-dependencies"]["docs"]]:
        match = BOUND.match(requirement)
        if match is None:
            raise SystemExit(f"no lower bound in {requirement!r}: every dependency needs one")
        lines.append(f"{match.group(1)}=={match.group(3)}")
    return lines


def main() -> None:
    if len(sys.argv) != 3 or sys.argv[1] != "lowest":
        raise SystemExit(__doc__)
    text = "# the lower bounds of pyproject.toml (scripts/constraints.py lowest)\n"
    Path(sys.argv[2]).write_text(text + "\n".join(lowest()) + "\n")


if __name__ == "__main__":
    main()
