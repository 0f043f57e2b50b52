"""``raysim simulate``: a scene -> a FieldMap (raysim.simulate over the optics engines)."""

from __future__ import annotations

from pathlib import Path

import typer

from raysim.cli.common import app, output_file, output_path, progress_bar, say
from raysim.methods import METHODS
from raysim.optics.fast import DEFAULT_TOL
from raysim.scene.scene import MAX_CELLS, MAX_N_PHI, MAX_N_THETA


@app.command()
def simulate(
    scene: Path = typer.Argument(..., help="Scene TOML file, or the name of a shipped example "
                                           "(raysim scenes lists them)."),
    output: Path = typer.Option(..., "-o", "--output", parser=output_file,
                                help="FieldMap NetCDF file to write."),
    method: str | None = typer.Option(None, "--method",
                                      help=f"{', '.join(METHODS)} (default: the scene's method "
                                           "key, else go)."),
    frequency: float | None = typer.Option(None, "--frequency",
                                           help="Override the scene's frequency (Hz), 1e6 to 1e13."),
    n_theta: int | None = typer.Option(
        None, "--n-theta", help=f"Cells in theta (polar angle from -z), 1 to {MAX_N_THETA}; "
                                f"n-theta x n-phi at most {MAX_CELLS:,} (as in the scene file)."),
    n_phi: int | None = typer.Option(None, "--n-phi", help=f"Cells in phi (azimuth), 1 to {MAX_N_PHI}."),
    device: str = typer.Option("cpu", "--device", help="Warp device: cpu or cuda."),
    total: bool = typer.Option(False, "--total",
                               help="Wave methods: intensity of scattered plus incident field."),
    save_field: bool = typer.Option(False, "--save-field",
                                    help="Wave methods: also store the complex field components E_re, E_im."),
    samples_per_wavelength: float | None = typer.Option(
        None, "--samples-per-wavelength",
        help="PO: Gauss points per wavelength along mesh face edges (default 1.5; 3-4 for "
             "field points near the surface, far from its focus)."),
    edges: str | None = typer.Option(
        None, "--edges",
        help="po+ptd: rim (the outer rim, default) or all (also every panel edge beside a gap)."),
    fresnel: bool = typer.Option(
        False, "--fresnel",
        help="go+edge: add the Fresnel-zone correction of the deformed geometric wave (wave "
             "optics' smoothing of features finer than the Fresnel zone; on the paper's dish "
             "it helps below about 3 GHz)."),
    radiator: str | None = typer.Option(
        None, "--radiator",
        help="po, po+ptd: fast (default: the multilevel sum, where its cost estimate beats the "
             "direct sum; the FieldMap records which ran) or direct (the reference sum)."),
    radiator_tol: float | None = typer.Option(
        None, "--radiator-tol",
        help=f"po, po+ptd: relative RMS accuracy of the fast radiator, in [1e-12, 1) (default "
             f"{DEFAULT_TOL:g})."),
    scheduler: str | None = typer.Option(
        None, "--scheduler",
        help="po, po+ptd: compute the sphere's points in blocks on the Dask scheduler at "
             "tcp://HOST:PORT (its workers need raysim and the output's folder)."),
    workers: int | None = typer.Option(
        None, "--workers",
        help="po, po+ptd: blocks on a local Dask cluster of N worker processes (default with "
             "--resume or --block-size: one per core, one per GPU with --device cuda)."),
    threads: int | None = typer.Option(
        None, "--threads", help="With --scheduler/--workers: CPU threads of each Warp launch (1)."),
    resume: bool = typer.Option(
        False, "--resume", help="Complete the blocks an interrupted --scheduler/--workers run left "
                                "in OUTPUT.partial.zarr."),
    block_size: int | None = typer.Option(
        None, "--block-size",
        help="With --scheduler/--workers: sphere points per block, a multiple of 4 (1024; 32768 "
             "on cuda)."),
) -> None:
    """Simulate a scene: intensity of the ideal and deformed reflector on the probe sphere.

    Writes a FieldMap (NetCDF): intensity relative to the incident plane wave on (theta, phi)
    cells, theta from -z at the focus and phi = atan2(y, x), both in radians in the file.
    """
    from raysim.maps.fieldmap import save
    from raysim.scene.scene import load_scene
    from raysim.simulate import check_options, summary
    from raysim.simulate import simulate as run

    loaded = load_scene(scene).with_overrides(frequency, n_theta, n_phi)
    method = method or loaded.method
    given_radiator = (radiator, radiator_tol) != (None, None)
    radiator = "fast" if radiator is None else radiator  # an empty --radiator is refused below
    radiator_tol = DEFAULT_TOL if radiator_tol is None else radiator_tol
    check_options(loaded, method=method, device=device, total=total, save_field=save_field,
                  samples_per_wavelength=samples_per_wavelength, edges=edges, fresnel=fresnel,
                  radiator=radiator, radiator_tol=radiator_tol)
    from raysim.dataset.run import MAX_THREADS, MAX_WORKERS
    from raysim.errors import RaysimError

    if given_radiator and method not in ("po", "po+ptd"):
        raise RaysimError("--radiator and --radiator-tol apply to --method po and po+ptd only")

    for name, value, hi in (("--workers", workers, MAX_WORKERS), ("--threads", threads, MAX_THREADS)):
        if value is not None and not 1 <= value <= hi:  # 0 is a count, not "off"
            raise RaysimError(f"{name} must be an integer in 1..{hi}, got {value}")
    blocks = scheduler or resume or any(v is not None for v in (workers, block_size, threads))
    if blocks and fresnel:
        raise RaysimError("--fresnel runs in this process: drop --scheduler, --workers, --resume, "
                          "--block-size and --threads")
    output_path(output, loaded.inputs())
    if blocks:
        _simulate_blocks(loaded, output, method, device, total=total, save_field=save_field,
                         samples_per_wavelength=samples_per_wavelength, edges=edges,
                         scheduler=scheduler, workers=workers, threads=threads or 1, resume=resume,
                         block_size=block_size, radiator=radiator, radiator_tol=radiator_tol)
        return
    with progress_bar() as bar:
        task = bar.add_task(f"{method} {loaded.name}", total=1.0)

        def report(stage: str, fraction: float) -> None:
            bar.update(task, completed=fraction, description=f"{method} {loaded.name}: {stage}")

        ds = run(loaded, method=method, device=device, progress=report, total=total,
                 save_field=save_field, samples_per_wavelength=samples_per_wavelength, edges=edges,
                 fresnel=fresnel, radiator=radiator, radiator_tol=radiator_tol)
    save(ds, output)
    say(f"{output}: {summary(ds)}")


def _simulate_blocks(scene, output: Path, method: str, device: str, **options) -> None:
    """``simulate`` in blocks of sphere points on Dask (raysim.distributed), a bar over blocks."""
    from raysim.distributed import simulate as run
    from raysim.simulate import summary

    with progress_bar() as bar:
        task = bar.add_task(f"{method} {scene.name}: blocks", total=1.0)

        def report(stage: str, fraction: float) -> None:
            bar.update(task, completed=fraction, description=f"{method} {scene.name}: {stage}")

        ds = run(scene, output, method, device, report, **options)
    a = ds.attrs
    workers_text = f"{a['workers']} worker" + ("" if a["workers"] == 1 else "s")
    say(f"{output}: {summary(ds)}; {a['blocks']} blocks on {workers_text} "
        f"({a['blocks_reused']} reused, {a['blocks_computed_twice']} computed twice"
        + (f", {a['blocks_repaired']} failed verification and were recomputed" if a.get("blocks_repaired")
           else "") + ")")
    if options.get("resume") and not a["blocks_reused"] and not a.get("blocks_repaired"):
        # as after an interrupt before the first block: the run's store was never kept
        say(f"--resume: no interrupted run of {output} was there to complete, so every block was "
            "computed afresh")
