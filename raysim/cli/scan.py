"""``raysim scan`` and ``raysim rig park``: the scanning rig (hardware.session)."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from raysim.cli.common import app, note_interrupt, output_file, output_path, progress_bar, say
from raysim.errors import RaysimError

rig_app = typer.Typer(help="The scanning rig (track, slider, rotation, power meter).",
                      no_args_is_help=True)
app.add_typer(rig_app, name="rig")


def _vector3(text: str | None, option: str) -> tuple[float, float, float] | None:
    """'X,Y,Z' (m) to a tuple, or None."""
    if text is None:
        return None
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3:
        raise RaysimError(f"{option} '{text}': give three numbers X,Y,Z in metres")
    return values  # type: ignore[return-value]


@app.command()
def scan(
    plan: Path = typer.Argument(..., help="Scan plan (TOML), or a shipped example's name "
                                          "(scan_demo)."),
    output: Path = typer.Option(..., "-o", "--output", parser=output_file,
                                help="Measured FieldMap to write (.nc)."),
    resource: list[str] | None = typer.Option(
        None, "--resource", help="Instrument address ROLE=VISA, ROLE meter or motion (twice)."),
    simulate: Path | None = typer.Option(
        None, "--simulate", help="Scan this FieldMap with a simulated rig on loopback sockets."),
    resume: bool = typer.Option(False, "--resume", help="Continue the journal of a stopped scan "
                                "(refused when there is none)."),
    rig: Path | None = typer.Option(None, "--rig", help="Rig file (TOML) over the plan's."),
    journal: Path | None = typer.Option(None, "--journal", help="Journal file [OUTPUT.journal]."),
    from_journal: bool = typer.Option(
        False, "--from-journal", help="Write the FieldMap from the journal alone (no rig)."),
    seed: int | None = typer.Option(None, "--seed", help="Simulator: noise and drift seed (>= 0)."),
    noise_db: float | None = typer.Option(None, "--noise-db",
                                          help="Simulator: noise (dB rms), 0 to 10."),
    drift_db: float | None = typer.Option(None, "--drift-db",
                                          help="Simulator: drift amplitude (dB), 0 to 10."),
    centre_offset: str | None = typer.Option(
        None, "--centre-offset", help="Simulator: true track-centre offset X,Y,Z from the "
        "focus (m)."),
    time_scale: float | None = typer.Option(
        None, "--time-scale", help="Simulator: move-time factor, 0 to 1000 (0 instant, 1 real "
                                   "time)."),
) -> None:
    """Scan the hemisphere with the rig (or a simulated one) into a measured FieldMap.

    Every completed sample is journaled to disk first; after a stop (Ctrl-C, kill, an
    instrument fault) the same command with --resume continues where it stopped.
    """

    from hardware.session import fieldmap_file_from_journal, journal_path, scan_files

    inputs = [("FieldMap the simulated rig scans", simulate)]
    output_path(output, inputs)
    if from_journal:
        ds = fieldmap_file_from_journal(plan, output, rig=rig, journal=journal)
        say(f"wrote {output} from the journal: {ds.attrs['samples_measured']} of "
            f"{ds.attrs['samples_expected']} samples{_drift_note(ds.attrs)}")
        return
    options = {"seed": seed, "noise_db": noise_db, "drift_db": drift_db,
               "centre_offset": _vector3(centre_offset, "--centre-offset"), "time_scale": time_scale}
    done = [0, 0]

    columns = (TextColumn("scan"), BarColumn(), MofNCompleteColumn(), TextColumn("elapsed"),
               TimeElapsedColumn(), TextColumn("left"), TimeRemainingColumn())
    try:
        with progress_bar(*columns, transient=False) as bar:
            task = bar.add_task("scan", total=None)

            def progress(stage: str, fraction: float) -> None:
                # stage "step <done> of <total>" (hardware.acquire.step_progress)
                steps_done, steps_total = (int(n) for n in stage.split()[1::2])
                if done[1] == 0:
                    bar.reset(task, total=steps_total, completed=steps_done)
                bar.update(task, completed=steps_done)
                done[:] = [steps_done, steps_total]

            result = scan_files(plan, output, rig=rig, journal=journal, resources=resource,
                                simulate=simulate, resume=resume, sim_options=options,
                                progress=progress)
    except KeyboardInterrupt:  # SIGINT or SIGTERM: the one interrupt line (raysim.cli.main)
        kept = Path(journal or journal_path(output))
        # before the first step the session removes the journal it made: say so, not "0 of 0"
        if kept.is_file():
            note_interrupt(f"{done[0]} of {done[1]} steps are in {kept}")
        else:  # nothing a --resume could continue (it would refuse): do not offer one
            note_interrupt(f"no step taken, no journal kept at {kept}", resumable=False)
        raise
    ds = result.fieldmap
    say(f"wrote {result.output}: {ds.attrs['samples_measured']} samples, "
        f"{result.steps_taken} of {result.steps_total} steps taken now (journal {result.journal})"
        f"{_drift_note(ds.attrs)}")


def _drift_note(attrs: dict) -> str:
    """What the summary line adds when the drift correction was not the one asked for
    (``drift_note``, :mod:`hardware.drift`): '' when it was."""
    note = str(attrs.get("drift_note", ""))
    return f"; drift: {note}" if note else ""


@rig_app.command("park")
def rig_park(
    rig: Path = typer.Argument(..., help="Rig file (TOML), or a shipped example's name (rig)."),
    resource: list[str] | None = typer.Option(
        None, "--resource", help="Motion controller address motion=VISA (over the rig file's)."),
    simulate: bool = typer.Option(False, "--simulate", help="Park a simulated rig (no --resource)."),
) -> None:
    """Move the probe to the park position that clears the optical path."""
    import math

    from hardware.rig import load_rig
    from hardware.session import park, parse_resources

    addresses = parse_resources(resource)
    rig_obj, _ = load_rig(rig)
    slider, rotation = park(rig_obj, resources=addresses, simulate=simulate)
    say(f"parked: slider {math.degrees(slider):.4f} deg, rotation {math.degrees(rotation):.4f} deg")
