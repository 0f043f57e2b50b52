"""``raysim scan`` and ``raysim rig park``: the scanning rig (hardware)."""

from __future__ import annotations

from pathlib import Path

import typer

from raysim.cli.common import app, console, out, output_path
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
    plan: Path = typer.Argument(..., help="Scan plan (TOML), e.g. scenes/scan_demo.toml."),
    output: Path = typer.Option(..., "-o", "--output", help="Measured FieldMap to write (.nc)."),
    resource: list[str] | None = typer.Option(
        None, "--resource", help="Instrument address ROLE=VISA, ROLE meter or motion (twice)."),
    simulate: Path | None = typer.Option(
        None, "--simulate", help="Scan this FieldMap with a simulated rig on loopback sockets."),
    resume: bool = typer.Option(False, "--resume", help="Continue the journal of a stopped scan."),
    rig: Path | None = typer.Option(None, "--rig", help="Rig file (TOML) over the plan's."),
    journal: Path | None = typer.Option(None, "--journal", help="Journal file [OUTPUT.journal]."),
    from_journal: bool = typer.Option(
        False, "--from-journal", help="Write the FieldMap from the journal alone (no rig)."),
    seed: int | None = typer.Option(None, "--seed", help="Simulator: noise and drift seed."),
    noise_db: float | None = typer.Option(None, "--noise-db", help="Simulator: noise (dB rms)."),
    drift_db: float | None = typer.Option(None, "--drift-db",
                                          help="Simulator: drift amplitude (dB)."),
    centre_offset: str | None = typer.Option(
        None, "--centre-offset", help="Simulator: true track-centre offset X,Y,Z from the "
        "focus (m)."),
    time_scale: float | None = typer.Option(
        None, "--time-scale", help="Simulator: move-time factor (0 instant, 1 real time)."),
) -> None:
    """Scan the hemisphere with the rig (or a simulated one) into a measured FieldMap.

    Every completed sample is journaled to disk first; after a stop (Ctrl-C, kill, an
    instrument fault) the same command with --resume continues where it stopped.
    """
    import dataclasses
    import signal

    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from hardware.plan import load_plan
    from hardware.session import fieldmap_from_journal, journal_path, parse_resources
    from hardware.session import scan as run_scan
    from raysim.maps.fieldmap import save

    scan_plan = load_plan(plan, rig=rig)
    output = output_path(output)
    if from_journal:
        ds = fieldmap_from_journal(scan_plan, journal or journal_path(output))
        save(ds, output)
        out.print(f"wrote {output} from the journal: {ds.attrs['samples_measured']} of "
                  f"{ds.attrs['samples_expected']} samples")
        return
    overrides = {"seed": seed, "noise_db": noise_db, "drift_db": drift_db,
                 "centre_offset": _vector3(centre_offset, "--centre-offset"),
                 "time_scale": time_scale}
    for name in ("noise_db", "drift_db", "time_scale"):
        if overrides[name] is not None and not 0.0 <= overrides[name] < 1e3:
            raise RaysimError(f"--{name.replace('_', '-')} must be >= 0")
    sim = dataclasses.replace(scan_plan.simulator,
                              **{k: v for k, v in overrides.items() if v is not None})
    done = [0, len(scan_plan.steps())]

    def on_signal(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, on_signal)
    columns = (TextColumn("scan"), BarColumn(), MofNCompleteColumn(), TextColumn("elapsed"),
               TimeElapsedColumn(), TextColumn("left"), TimeRemainingColumn())
    try:
        with Progress(*columns, console=console, disable=not console.is_terminal) as bar:
            task = bar.add_task("scan", total=done[1])

            def progress(stage: str, fraction: float) -> None:
                done[0] = round(fraction * done[1])
                bar.update(task, completed=done[0])

            result = run_scan(scan_plan, output, resources=parse_resources(resource),
                              simulate=simulate, sim=sim, resume=resume, journal=journal,
                              progress=progress)
    except KeyboardInterrupt:
        where = journal or journal_path(output)
        console.print(f"[bold red]interrupted:[/] {done[0]} of {done[1]} steps are in {where}; "
                      "run the same command with --resume to continue", highlight=False)
        raise typer.Exit(code=130) from None
    finally:
        signal.signal(signal.SIGTERM, previous)
    ds = result.fieldmap
    out.print(f"wrote {result.output}: {ds.attrs['samples_measured']} samples, "
              f"{result.steps_taken} of {result.steps_total} steps taken now "
              f"(journal {result.journal})")


@rig_app.command("park")
def rig_park(
    rig: Path = typer.Argument(..., help="Rig file (TOML), e.g. scenes/rig.toml."),
    resource: list[str] | None = typer.Option(
        None, "--resource", help="Motion controller address motion=VISA."),
    simulate: bool = typer.Option(False, "--simulate", help="Park a simulated rig."),
) -> None:
    """Move the probe to the park position that clears the optical path."""
    import math

    from hardware.rig import load_rig
    from hardware.session import park, parse_resources

    rig_obj, _ = load_rig(rig)
    slider, rotation = park(rig_obj, resources=parse_resources(resource), simulate=simulate)
    out.print(f"parked: slider {math.degrees(slider):.4f} deg, rotation "
              f"{math.degrees(rotation):.4f} deg")
