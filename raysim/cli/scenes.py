"""``raysim scenes``: the shipped examples (scenes, scan plans, the rig file, dataset specs)."""

from __future__ import annotations

from pathlib import Path

import typer

from raysim.cli.common import app, say

scenes_app = typer.Typer(
    help="The shipped examples: scenes, scan plans, the rig file and dataset specs. Any "
         "command that takes a file also takes an example's name (raysim simulate paper_go ...); "
         "a path that exists always wins.",
    invoke_without_command=True)
app.add_typer(scenes_app, name="scenes")


@scenes_app.callback()
def scenes(ctx: typer.Context) -> None:
    """List the shipped examples, one line each: name, kind, description."""
    if ctx.invoked_subcommand is not None:
        return
    from raysim.files import example, example_names, example_summary

    names = example_names()
    width = max((len(n) for n in names), default=0)
    for name in names:
        kind, description = example_summary(example(name))
        say(f"{name:{width}s}  {kind:12s}  {description}")


@scenes_app.command("copy")
def copy(
    name: str = typer.Argument(..., help="The example's name (raysim scenes lists them)."),
    folder: Path = typer.Argument(..., help="Folder to write the copy into (created if needed)."),
) -> None:
    """Write an editable copy of an example (and the files it names, e.g. a plan's rig file)."""
    from raysim.files import copy_example

    for path in copy_example(name, folder):
        say(f"wrote {path}")
