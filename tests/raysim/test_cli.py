"""The raysim command as a user meets it: outputs, summaries, and one line for each mistake."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from raysim.maps.fieldmap import load
from tests.cli import run_cli

SMALL = """
name = "small"
[dish]
diameter_m = 20.0
focal_length_m = 8.0
resolution_m = 0.5

[[deformation]]
type = "bumps"
bumps = [{x_m = 3.0, y_m = 2.0, amplitude_um = 300.0, sigma_m = 2.0}]

[source]
frequency_hz = 1.0e9

[sphere]
radius_m = 3.0
n_theta = 30
n_phi = 60
"""


@pytest.fixture()
def scene_file(tmp_path: Path) -> Path:
    path = tmp_path / "small.toml"
    path.write_text(SMALL)
    return path


def test_simulate_writes_a_fieldmap_and_one_summary_line(tmp_path: Path, scene_file: Path):
    out = tmp_path / "out" / "small.nc"
    run = run_cli("simulate", str(scene_file), "-o", str(out), cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    line = run.stdout.strip()
    assert line.startswith(str(out)) and "1800 points" in line and "power balance" in line
    assert "\n" not in line
    ds = load(out)
    assert ds.attrs["method"] == "go" and ds.attrs["scene"] == SMALL
    assert abs(ds.attrs["power_balance"]) < 1e-9
    # the bump shows in the ratio, the ideal map does not depend on it
    lit = ds["intensity"].values > 0
    FA = ds["intensity_ideal"].values[lit] / ds["intensity"].values[lit] - 1
    assert np.abs(FA).max() > 1e-3


def test_a_resume_with_nothing_to_resume_says_it_started_afresh(tmp_path: Path, scene_file: Path):
    """``simulate --resume`` without an interrupted run's blocks computed every block anew and
    said "0 reused", as a resume that found its store lost would; and "1 workers"."""
    out = tmp_path / "po.nc"
    run = run_cli("simulate", str(scene_file), "-o", str(out), "--method", "po", "--workers", "1",
                  "--resume", cwd=tmp_path, timeout=300)
    assert run.returncode == 0, run.stderr
    first, second = run.stdout.strip().splitlines()
    assert " blocks on 1 worker (0 reused" in first
    assert second == (f"--resume: no interrupted run of {out} was there to complete, so every "
                      "block was computed afresh")


def test_overrides_reach_the_output(tmp_path: Path, scene_file: Path):
    out = tmp_path / "o.nc"
    run = run_cli("simulate", str(scene_file), "-o", str(out), "--n-theta", "10", "--n-phi", "20",
                 "--frequency", "3e9", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    ds = load(out)
    assert ds.sizes == {"theta": 10, "phi": 20} and ds.attrs["frequency_hz"] == 3e9


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["simulate", "missing.toml", "-o", "x.nc"], "missing.toml: no such scene file"),
        (["simulate", "{scene}", "-o", "x.nc", "--frequency", "0.3"], "--frequency = 0.3 is in Hz"),
        (["simulate", "{scene}", "-o", "x.nc", "--method", "magic"], "unknown method 'magic'"),
        (["simulate", "{scene}", "-o", "x.nc", "--device", "tpu"], "unknown device 'tpu'"),
        (["simulate", "{scene}", "-o", "/proc/x.nc"], "cannot write in /proc"),
    ],
)
def test_user_errors_are_one_line_and_status_2(tmp_path: Path, scene_file: Path, args, message):
    args = [a.replace("{scene}", str(scene_file)) for a in args]
    run = run_cli(*args, cwd=tmp_path)
    assert run.returncode == 2
    assert message in run.stderr
    assert "Traceback" not in run.stderr and len(run.stderr.strip().splitlines()) == 1


def test_bad_scene_key_names_the_key(tmp_path: Path):
    bad = tmp_path / "bad.toml"
    bad.write_text(SMALL.replace("radius_m = 3.0", "radius_m = 9.0"))
    run = run_cli("simulate", str(bad), "-o", "x.nc", cwd=tmp_path)
    assert run.returncode == 2 and "'sphere.radius_m' = 9 m must be smaller than the focal length" in run.stderr


def test_a_failed_run_leaves_the_previous_output(tmp_path: Path, scene_file: Path):
    out = tmp_path / "keep.nc"
    assert run_cli("simulate", str(scene_file), "-o", str(out), cwd=tmp_path).returncode == 0
    before = out.read_bytes()
    run = run_cli("simulate", str(scene_file), "-o", str(out), "--method", "magic", cwd=tmp_path)
    assert run.returncode == 2 and out.read_bytes() == before


def test_help_explains_units(tmp_path: Path):
    run = run_cli("--help", cwd=tmp_path)
    assert run.returncode == 0 and "metres" in run.stdout and "Hz" in run.stdout
    sim = run_cli("simulate", "--help", cwd=tmp_path)
    assert "(Hz)" in sim.stdout and "radians" in sim.stdout


def _broken_early(lines: list[str], width: int) -> list[str]:
    """Lines of a paragraph (consecutive non-blank ``lines``) that end although the next one's
    first word would have fitted after them: a line break the text carried, not the wrap."""
    out = []
    for a, b in itertools.pairwise(lines):
        if a.strip() and b.strip():
            room = width - 2 - len(a.rstrip())
            if len(b.split()[0]) + 1 <= room:
                out.append(a.strip())
    return out


@pytest.mark.parametrize("args", [(), ("budget",), ("check",), ("correct",), ("dataset",), ("scan",),
                                  ("simulate",), ("report",)])
def test_help_text_wraps_to_the_terminal(tmp_path: Path, args: tuple[str, ...]):
    """At 80 columns, the command's description wraps at the terminal's width, and the root's
    list of commands within its column: the docstrings' own line breaks cut sentences
    mid-way ("... the inversion's linear" / "operator (no Monte Carlo) ...")."""
    from tests.cli import cli_env

    run = run_cli(*args, "--help", cwd=tmp_path, env=cli_env(COLUMNS="80"))
    assert run.returncode == 0
    lines = run.stdout.splitlines()
    if not args:  # the commands' box: "│ name    summary │", continuations start with blanks
        box = lines[next(i for i, line in enumerate(lines) if "Commands" in line):]
        rows: list[list[str]] = []
        for line in (line for line in box if line.startswith("│ ")):
            cell = line.strip("│ ")
            if line.startswith("│           ") and rows:
                rows[-1].append(cell)
            else:
                rows.append([cell.split(None, 1)[-1]])
        broken = [b for row in rows for b in _broken_early(row, 80 - 14)]
    else:  # the description: between the usage line and the first box
        top = next(i for i, line in enumerate(lines) if line.lstrip().startswith("╭"))
        broken = _broken_early([line for line in lines[2:top]], 80)
    assert broken == []


def test_an_option_missing_its_value_names_the_command(tmp_path: Path):
    """The framework does not say which command an option without its value belongs to; the
    line named the root and sent the user to the root's help."""
    run = run_cli("simulate", "paper_go", "-o", cwd=tmp_path)
    assert run.returncode == 2
    assert run.stderr.splitlines() == [
        "error: raysim simulate: Option '-o' requires an argument. (see 'raysim simulate --help')"]


def test_an_ascii_terminal_gets_escapes_not_a_traceback(tmp_path: Path):
    """Under an ASCII locale with the output's encoding ASCII, a command that had written its
    file ended in a UnicodeEncodeError traceback when it named a non-ASCII path."""
    from tests.cli import cli_env

    scene = tmp_path / "small.toml"
    scene.write_text(SMALL)
    run = run_cli("simulate", scene, "-o", tmp_path / "dïsh µ.nc", cwd=tmp_path,
                  env=cli_env(LC_ALL="C", PYTHONIOENCODING="ascii"))
    assert run.returncode == 0, run.stderr
    assert (tmp_path / "dïsh µ.nc").is_file()
    assert "d\\xefsh \\xb5.nc" in run.stdout and "Traceback" not in run.stderr


def test_a_dish_deeper_than_a_hemisphere_can_scan_is_said_so():
    """QA: a dish of F/D 0.2 (rim image at 102.7 deg) simulated without a word while the
    hemisphere missed a third of its power. GO's power on the hemisphere is the aperture's
    share inside r(90 deg) = 2F, (4F/D)^2 = 0.64 of it; the summary warns, and a dish of F/D
    0.3 (rim image 79.6 deg) gets no such line."""
    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate, summary

    def scene(F):
        return parse_scene(f"""name = "deep"
[dish]
diameter_m = 10.0
focal_length_m = {F}
resolution_m = 0.3
[source]
frequency_hz = 1e9
[sphere]
radius_m = 1.0
n_theta = 30
n_phi = 36
""")

    deep = simulate(scene(2.0))
    assert deep.attrs["power_balance"] == pytest.approx((4 * 2.0 / 10.0) ** 2 - 1.0, abs=0.01)
    assert "WARNING: the rim image lies at 102.7 deg from the axis, beyond the hemisphere" in summary(deep)
    shallow = simulate(scene(3.0))
    assert abs(shallow.attrs["power_balance"]) < 0.01 and "rim image" not in summary(shallow)


def test_go_says_when_the_dish_or_the_sphere_is_out_of_its_reach():
    """QA: a 10 m dish at 50 MHz (1.7 wavelengths) and a sphere of 1 mm about the focus (GO's
    caustic: a peak of 2.7e7 where PO gives 2.2e3) ran GO without a word. The summary now
    gives the dish in wavelengths, D f / c, and the sphere's radius in focal-spot widths,
    lambda F / D, where they are small; a large dish and sphere get neither line."""
    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate, summary

    def run(f, R):
        return summary(simulate(parse_scene(f"""name = "reach"
[dish]
diameter_m = 10.0
focal_length_m = 4.0
resolution_m = 0.3
[source]
frequency_hz = {f}
[sphere]
radius_m = {R}
n_theta = 12
n_phi = 12
""")))

    c = 299_792_458.0
    small = run(0.25e9, 1.0)
    assert f"the dish is {10.0 * 0.25e9 / c:.3g} wavelengths across" in small
    assert f"the sphere's radius is {1.0 / (c / 0.25e9 * 4.0 / 10.0):.3g} focal-spot widths" in small
    large = run(3e9, 3.0)
    assert "wavelengths across" not in large and "focal-spot widths" not in large


@pytest.mark.parametrize("degrees", [36.7, 40.7])
def test_po_says_when_the_dish_shadows_part_of_itself(degrees):
    """QA: at 55 deg on a 10 m dish of F = 2 m, PO erred by 25 % in E on 1 m faces (14 % on
    0.5 m, 1.5 % on 0.125 m) against an independent PO integral, and said nothing. The wave
    starts to shadow part of the concave face where the smooth normal's n . k changes sign
    inside the rim: found here on the paraboloid's normals directly, two degrees either side
    of atan(4F / D) = 38.7 deg, and the summary warns exactly when it happens."""
    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate, summary

    D, F, theta = 10.0, 2.0, np.radians(degrees)
    r = np.linspace(0.0, D / 2, 400)[:, None]
    phi = np.linspace(0.0, 2 * np.pi, 720)[None, :]
    x, y = r * np.cos(phi), r * np.sin(phi)
    normal = np.stack([-x / (2 * F), -y / (2 * F), np.ones_like(x)])  # up the concave face
    arriving = -np.array([np.sin(theta), 0.0, np.cos(theta)])[:, None, None]  # scene.py's
    n_dot_k = np.sum(normal * arriving, axis=0)
    shadows_itself = bool(np.any(n_dot_k > 0))  # a patch of the front facing away from the wave
    line = summary(simulate(parse_scene(f"""name = "tilted"
[dish]
diameter_m = {D}
focal_length_m = {F}
resolution_m = 1.0
[source]
frequency_hz = 0.1e9
incidence_theta_deg = {degrees}
[sphere]
radius_m = 1.0
n_theta = 6
n_phi = 12
"""), method="po"))
    assert shadows_itself == (degrees > 38.7)
    assert ("beyond the rim's tangent at 38.7 deg" in line) == shadows_itself, line


def test_go_whose_rays_all_miss_the_grid_says_why():
    """QA: at 30 deg incidence every reflected ray of a 10 m dish (F = 4 m) passes beyond the
    hemisphere about the focus, and simulate ended with the FieldMap's check, 'no ideal
    intensity', which says nothing of why."""
    from raysim.errors import RaysimError
    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate

    scene = parse_scene("""name = "tilted"
[dish]
diameter_m = 10.0
focal_length_m = 4.0
resolution_m = 0.3
[source]
frequency_hz = 3e9
incidence_theta_deg = 40.0
[sphere]
radius_m = 2.0
n_theta = 12
n_phi = 12
""")
    with pytest.raises(RaysimError, match="no GO ray of the ideal dish reached the sphere's cells "
                                          r"\(incidence 40 deg"):
        simulate(scene)
