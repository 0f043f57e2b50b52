"""``python -m raysim.cli``: the console script."""

from raysim.cli import main

if __name__ == "__main__":
    main()
