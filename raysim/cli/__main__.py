"""``python -m raysim.cli``: the console script."""

from raysim.cli import main

main()
