"""A measurement campaign end to end, simulated: budget -> field -> rig scan -> rim targets -> map.

Units: lengths in m (the summary's figures in um), noise in dB per reading, times in s.

``raysim campaign SCENE PLAN -o DIR`` runs what a surface crew would do, with the truth known:

1. the budget (:mod:`raysim.pipeline.budget`) picks the readings per point a target RMS needs
   at the plan's noise (or the plan's own ``samples_per_point``);
2. the scene (the telescope as it is: deformation, obstacles, probe) is simulated in GO; the
   plan must carry the scene's obstacles (its ``[[obstacle]]`` tables), whose shadows the
   measured map then marks and the budget counts as cells without data;
3. the plan is scanned through the simulated rig on loopback sockets (the PyVISA drivers, the
   plan's noise, drift and unknown gain ``[simulator] gain_db``), at the budget's averaging;
4. rim targets, as a laser tracker or photogrammetry would give them: the scene's deformation
   at N points on the rim plus Gaussian errors of ``rim_std``;
5. the measured scan is inverted as any measured scan is (gain estimated, delta_c removed,
   the rim targets fixing the harmonic part) and compared with the truth.

6. when the scene has panels, the correction (docs/correction.md): the corner actuators'
   commands from the measured map, with the command error each actuator inherits from the
   budget's map error (:mod:`solver.correction_budget`), beside the error the commands really
   have (against the commands the true surface asks for).

The folder gets ``field.nc``, ``scan.nc`` (and its journal), ``rim.csv``, ``surface.nc``,
``commands.csv`` (with panels) and ``campaign.txt`` (the summary: the budget's prediction beside
the RMS reached).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from hardware.plan import ScanPlan, load_plan
from hardware.session import check_map_holds_plan, scan
from raysim.files import write_text
from raysim.maps import fieldmap as fieldmaps
from raysim.maps import surfacemap as surfacemaps
from raysim.pipeline.budget import budget_rows
from raysim.pipeline.report import output_folder, staging
from raysim.progress import Progress
from raysim.scene.scene import Scene, load_scene
from raysim.simulate import simulate
from raysim.surface.obstacles import ObstacleMesh, obstacle_mesh
from solver.boundary import RimTargets, write_rim_csv
from solver.errors import SolverError
from solver.invert import invert

FILES = ("field.nc", "scan.nc", "scan.nc.journal", "rim.csv", "surface.nc", "campaign.txt",
         "commands.csv")


@dataclass(frozen=True)
class CampaignResult:
    """What the campaign predicted and reached (m), with the choices it made."""

    folder: Path
    readings: int
    predicted: float
    achieved: float
    hours: float
    gain_injected: float
    gain_estimated: float
    lines: tuple[str, ...]


def rim_targets(deformation, a: float, n: int, std: float, seed: int) -> RimTargets:
    """``n`` targets evenly spaced on the rim r = a, dz = the deformation there plus N(0, std)."""
    phi = 2.0 * np.pi * (np.arange(n) + 0.5) / n
    x, y = a * np.cos(phi), a * np.sin(phi)
    dz = np.asarray(deformation(x, y), dtype=np.float64)
    dz = dz + std * np.random.default_rng(seed).standard_normal(n)
    return RimTargets(x, y, dz, source=f"{n} simulated rim targets ({std * 1e6:g} um each)")


def run_campaign(scene_path: str | os.PathLike[str], plan_path: str | os.PathLike[str],
                 out_dir: str | os.PathLike[str], *, rim: int = 64, rim_std: float = 10e-6,
                 target: float | None = None, readings: int | None = None, N: int = 256,
                 refine: int = 3, seed: int = 0, progress: Progress | None = None
                 ) -> CampaignResult:
    """Run the campaign of the module docstring; see ``raysim campaign --help`` for each option.

    ``target`` (m): let the budget choose the readings per point for it; ``readings``: fix
    them (neither: the plan's ``samples_per_point``).
    """
    report = progress or (lambda stage, fraction: None)
    scene = load_scene(scene_path)
    plan = load_plan(plan_path)
    if target is not None and readings is not None:
        raise SolverError("give --target-um or --readings, not both")
    if scene.dish.focal_length is None or scene.dish.diameter is None:
        raise SolverError("a campaign needs a scene whose [dish] gives diameter_m and "
                          "focal_length_m")
    if abs(plan.focal_length - scene.dish.focal_length) > 1e-9 * scene.dish.focal_length or \
            abs(plan.diameter - scene.dish.diameter) > 1e-9 * scene.dish.diameter:
        raise SolverError(f"the plan's reflector (F {plan.focal_length:g} m, D {plan.diameter:g} m) "
                          f"is not the scene's dish (F {scene.dish.focal_length:g} m, "
                          f"D {scene.dish.diameter:g} m)")
    check_obstacles(scene, plan)
    plan.check_tolerance()  # its scan would refuse it only after the scene was simulated
    check_map_holds_plan(plan, scene.sphere, scene.source.frequency_hz, f"the scene {scene_path}",
                         "give the scene a [sphere] of the rig's radius that holds the plan's grid, "
                         "and the plan's frequency")
    # the files the scene names (a map an earlier campaign measured) are inputs too: a
    # folder holding one would be replaced with the input inside it
    folder = output_folder(out_dir, [("scene", scene_path), *scene.inputs(), *plan.inputs()], FILES,
                           "a raysim campaign", "campaign.txt")
    noise = plan.simulator.noise_db
    if not noise > 0:
        raise SolverError("the plan's [simulator] noise_db must be above 0 for a campaign")
    row = budget_rows(plan, [noise], readings, rim, rim_std, refine=refine > 0, target=target)[0]
    k = row.readings if target is None else row.readings_needed
    if k is None:
        fixed = math.hypot(row.budget.harmonic or 0.0, row.budget.reference)
        raise SolverError(f"the rim targets and the drift references alone leave {fixed * 1e6:.1f} "
                          f"um: the target {target * 1e6:g} um is out of reach at any readings "
                          "per point")
    if target is not None:
        row = budget_rows(plan, [noise], k, rim, rim_std, refine=refine > 0)[0]
    # the rig's time comes from the budget row (with the plan's settling); the simulated
    # axes arrive at once (time_scale 0), so the simulated scan does not wait to settle
    plan = replace(plan, samples_per_point=k, settle_s=0.0)
    a = 0.5 * scene.dish.diameter
    with staging(folder) as tmp:
        report("simulate", 0.0)
        field = simulate(scene, method="go")
        fieldmaps.save(field, tmp / "field.nc")
        report("scan", 0.2)
        measured = scan(plan, tmp / "scan.nc", simulate=tmp / "field.nc",
                        sim=replace(plan.simulator, time_scale=0.0),
                        progress=lambda stage, f: report(f"scan: {stage}", 0.2 + 0.6 * f)).fieldmap
        targets = rim_targets(scene.deformation, a, rim, rim_std, seed) if rim else None
        if targets is not None:
            write_rim_csv(targets, tmp / "rim.csv")
        report("invert", 0.8)
        surface = invert(measured, rim=targets, N=N, refine_iterations=refine,
                         truth=scene.deformation)
        surfacemaps.save(surface, tmp / "surface.nc")
        result = CampaignResult(folder, k, row.budget.total, float(surface.attrs["rms_m"]),
                                row.hours, 10 ** (plan.simulator.gain_db / 10),
                                float(surface.attrs["gain"]), ())
        lines = summary_lines(result, noise, rim, rim_std, surface.attrs)
        if scene.panels is not None:
            lines += correction_lines(scene, plan, surface, tmp / "commands.csv", noise, k, rim,
                                      rim_std, refine)
        write_text(tmp / "campaign.txt", "\n".join(lines) + "\n")
    report("done", 1.0)
    return replace(result, lines=tuple(lines))


def check_obstacles(scene: Scene, plan: ScanPlan) -> None:
    """Refuse a plan whose ``[[obstacle]]`` tables do not put the scene's obstacles in the beam
    (compared as triangles on the dish): the measured map marks the cells the plan's hide."""
    ours = obstacle_mesh(scene.obstacles, plan.focal_length)
    theirs = plan.obstacle_mesh
    if ours == theirs:
        return

    def words(mesh: ObstacleMesh | None) -> str:
        return "none" if mesh is None else f"({mesh.description})"

    raise SolverError(f"the plan's obstacles {words(theirs)} are not the scene's {words(ours)}: "
                      "give the plan the scene's [[obstacle]] tables")


def summary_lines(result: CampaignResult, noise_db: float, rim: int, rim_std: float,
                  attrs: dict) -> list[str]:
    """The campaign's summary: the choices, the prediction beside the figure reached."""
    targets = f"{rim} rim targets of {rim_std * 1e6:g} um" if rim else "no rim targets"
    return [
        f"scan: {noise_db:g} dB per reading, {result.readings} readings per point "
        f"({result.hours:.1f} h on the rig), {targets}",
        f"gain: {result.gain_injected:.6f} unknown to the plan, estimated {result.gain_estimated:.6f}"
        f" +- {attrs.get('gain_std', 0.0):.1e} (the readings' noise alone: a deformed dish moves "
        "the estimate further); delta_c removed "
        f"({1e6 * attrs.get('removed_delta_c_centre_m', 0.0):.1f} um at the centre)",
        f"predicted RMS (raysim budget): {result.predicted * 1e6:.1f} um",
        f"achieved RMS against the truth: {result.achieved * 1e6:.1f} um",
    ] + [f"WARNING (the map's, from the inversion): {value}" for key, value in attrs.items()
         if key.endswith("_warning")]  # a map beyond the model's reach, mostly noise, ...


def correction_lines(scene: Scene, plan: ScanPlan, surface, path: Path, noise_db: float,
                     readings: int, rim: int, rim_std: float, refine: int) -> list[str]:
    """Correct the measured map with the corner actuators (piston and tilt left to pointing),
    write the commands with the error each inherits from the budget (``command_std_um``), and
    say what they leave and how far they are from the commands the true surface asks for."""
    from raysim.pipeline.budget import used_cells
    from solver.actuators import corners_layout
    from solver.budget import noise_response, relative_std
    from solver.correction import correct
    from solver.correction_budget import budget_shapes, command_std_from_budget
    from solver.correction_io import CorrectionRun, commands_csv, header_lines, map_caveats

    layout = scene.panels
    acts = corners_layout(layout)
    grid = surfacemaps.grid_of(surface)
    terms = ("piston", "tilt")
    corr = correct(grid, surface["deformation"].values, layout, acts, terms)
    ideal = correct(grid, surface["truth"].values, layout, acts, terms)
    corrected = plan.drift_correction != "none"
    response = noise_response(plan.grid, plan.focal_length, plan.diameter,
                              "refocus" if refine > 0 else "linear",
                              plan.reference_every if corrected else None, used_cells(plan))
    v = relative_std(noise_db, readings) ** 2
    modes = [(m, n, v * ms) for m, n, ms in response.modes]
    if corrected and plan.reference_samples > 0:
        v_ref = relative_std(noise_db, plan.reference_samples) ** 2
        modes += [(m, n, v_ref * ms) for m, n, ms in response.reference if m > 0]
    corr.command_std = command_std_from_budget(grid, layout, acts, terms,
                                               budget_shapes(grid, modes, rim, rim_std))
    # what the map may not hold, in the file the crew loads, as raysim correct writes it
    corr.notes += map_caveats(surface.attrs, layout.n_panels)
    run = CorrectionRun(corr, acts, "um", (), np.array([]), np.array([]), [], [], [])
    path.write_text(commands_csv(run, header_lines(run, terms)), encoding="utf-8")
    predicted = float(np.sqrt(np.mean(corr.command_std**2)))
    actual = float(np.sqrt(np.mean((corr.commands - ideal.commands) ** 2)))
    return [
        f"correction: {acts.n_actuators} corner actuators, RMS {corr.rms_before * 1e6:.1f} um -> "
        f"{corr.rms_after * 1e6:.1f} um predicted (commands in commands.csv; + toward the focus)",
        f"command error from the budget: RMS {predicted * 1e6:.1f} um over the actuators "
        f"(max {np.max(corr.command_std) * 1e6:.1f} um); against the true surface's commands: "
        f"{actual * 1e6:.1f} um",
    ]
