"""Bad input, command by command: exit status 2, exactly one line on stderr, no traceback, and
every file that was there before byte-identical afterwards (inputs included).

One table of cases per command; each case names the arguments (``{name}`` stands for a file
of the workspace) and a piece of the expected message. The commands run in this process
(tests/cli.py), in a workspace holding every input the cases refer to.
"""

from __future__ import annotations

import os
import socket
import threading
from pathlib import Path

import numpy as np
import pytest

from raysim.maps.fieldmap import fieldmap, save
from raysim.maps.sphere import SphereGrid, ideal_go_intensity
from tests.raysim.test_cli import SMALL

F, D, R = 8.0, 20.0, 3.0

SCENE = SMALL.replace("n_theta = 30", "n_theta = 10").replace("n_phi = 60", "n_phi = 20")

PANELS = """
[panels]
ring_edges_m = {edges}
panels_per_ring = [1]
"""


def _scene(extra: str = "", **replace: str) -> str:
    text = SCENE
    for old, new in replace.items():
        text = text.replace(old.replace("__", " = "), new)
    return text + extra


def _obstacle_scene(table: str) -> str:
    return SCENE + "[[obstacle]]\n" + table + "\n"


LEGS = 'type = "legs"\ncount = 4\nwidth_m = 0.3\nfoot_radius_m = 7.0\n'


def _obstacle_plan(table: str, noisy: bool = False) -> str:
    plan = PLAN.replace("time_scale = 0.0", "time_scale = 0.0\nnoise_db = 0.01") if noisy else PLAN
    return plan + "[[obstacle]]\n" + table + "\n"


def _map_scene(name: str) -> str:
    return SCENE + f'[[deformation]]\ntype = "map"\nfile = "{name}"\n'


SPEC = """
name = "tiny"
samples = 2
seed = 1
scene = "scene.toml"
[[errors]]
type = "zernike"
rms_um = 10.0
"""

RIG = """
[track]
radius_m = 3.0
[instruments]
timeout_s = 0.5
"""

PLAN = """
rig = "rig.toml"
[reflector]
focal_length_m = 8.0
diameter_m = 20.0
frequency_hz = 1.0e9
[grid]
theta_max_deg = 60.0
theta_step_deg = 20.0
phi_step_deg = 90.0
[acquisition]
samples_per_point = 1
reference_samples = 1
[simulator]
time_scale = 0.0
"""


def _csv_map(rows) -> str:
    return "x,y,dz\n" + "".join(f"{x},{y},{dz}\n" for x, y, dz in rows)


def _grid_rows(dz=lambda x, y: 1e-4):
    values = np.linspace(-11.0, 11.0, 6)
    return [(x, y, dz(x, y)) for y in values for x in values]


def _edit_row(text: str, row: int, column: int, value: str) -> str:
    """``text`` (CSV) with the cell at data row ``row``, ``column`` replaced by ``value``."""
    lines = text.splitlines()
    cells = lines[row].split(",")
    cells[column] = value
    lines[row] = ",".join(cells)
    return "\n".join(lines) + "\n"


def _fieldmap(values=None):
    grid = SphereGrid(R, 10, 20)
    t, _ = np.meshgrid(grid.theta, grid.phi, indexing="ij")
    ideal = ideal_go_intensity(t, F, R, D)
    intensity = ideal * 1.001 if values is None else values(ideal)
    return fieldmap(grid, intensity, ideal, focal_length=F, diameter=D, frequency_hz=1e9,
                    method="go", sampling="cell_mean")


def _write_mesh_in_mm(path: Path) -> None:
    import trimesh

    from raysim.surface.mesh import paraboloid

    dish = paraboloid(D, F, 2.0)
    trimesh.Trimesh(dish.vertices * 1000.0, dish.faces).export(path)


def _silent_server() -> tuple[int, threading.Event]:
    """A TCP server on loopback that accepts and never answers (stops when the event is set)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    server.settimeout(0.2)
    stop = threading.Event()
    held = []

    def serve() -> None:
        while not stop.is_set():
            try:
                held.append(server.accept()[0])
            except OSError:
                pass
        for conn in held:
            conn.close()
        server.close()

    threading.Thread(target=serve, daemon=True).start()
    return server.getsockname()[1], stop


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """Every input the cases name, written once."""
    ws = tmp_path_factory.mktemp("bad_inputs")
    files = {
        "scene.toml": SCENE,
        "bad_toml.toml": "[dish\n",
        "typo.toml": _scene(diameter_m__20="diametre_m = 20"),
        "no_edges.toml": _scene(PANELS.format(edges="[]")),
        "nan_edge.toml": _scene(PANELS.format(edges="[0.0, nan, 10.0]")),
        "zernike_nan.toml": SCENE + '[[deformation]]\ntype = "zernike"\nterms = [[2, 2, nan]]\n',
        "paper_huge.toml": SCENE + '[[deformation]]\ntype = "paper"\nscale = 1e7\n',
        "fine_mesh.toml": _scene(resolution_m__0="resolution_m = 0.0006 #"),
        "units_um.toml": _map_scene("map_um.csv"),
        "text_cell.toml": _map_scene("map_text.csv"),
        "inf_cell.toml": _map_scene("map_inf.csv"),
        "nan_x.toml": _map_scene("map_nan_x.csv"),
        "corrupt_map.toml": _map_scene("corrupt.nc"),
        "mm_mesh.toml": SCENE.replace("diameter_m = 20.0\nfocal_length_m = 8.0",
                                      'focal_length_m = 8.0\nmesh = "dish_mm.stl"'),
        "big_sphere.toml": _scene(n_theta__10="n_theta = 100000"),
        "method_bad.toml": 'method = "fdtd"\n' + SCENE,
        "obst_kind.toml": _obstacle_scene('type = "tower"'),
        "obst_width.toml": _obstacle_scene(LEGS.replace("width_m = 0.3", "width_m = -0.3")),
        "obst_count.toml": _obstacle_scene(LEGS.replace("count = 4", "count = 0")),
        "obst_mm.toml": _obstacle_scene(LEGS.replace("width_m = 0.3", "width_m = 300.0")),
        "obst_foot.toml": _obstacle_scene(LEGS.replace("foot_radius_m = 7.0", "foot_radius_m = 12.0")),
        "obst_apex.toml": _obstacle_scene(LEGS + "apex_z_m = 1.0\n"),
        "obst_typo.toml": _obstacle_scene(LEGS + "rotation = 45.0\n"),
        "obst_disk.toml": _obstacle_scene('type = "disk"\nradius_m = 10.0'),
        "obst_nofile.toml": _obstacle_scene('type = "mesh"\nfile = "cabin.stl"'),
        "obst_junk.toml": _obstacle_scene('type = "mesh"\nfile = "notes.txt"'),
        "spec_obstacles.toml": SPEC.replace('scene = "scene.toml"', 'scene = "obst_ok.toml"'),
        "obst_ok.toml": _obstacle_scene(LEGS),
        "map_um.csv": _csv_map(_grid_rows(lambda x, y: 300.0)),
        "map_text.csv": _edit_row(_csv_map(_grid_rows()), 3, 2, "abc"),
        "map_inf.csv": _csv_map(_grid_rows(lambda x, y: np.inf if x > 10 else 1e-4)),
        "map_nan_x.csv": _edit_row(_csv_map(_grid_rows()), 1, 0, "nan"),
        "spec.toml": SPEC,
        "spec_typo.toml": SPEC.replace("seed = 1", "sede = 1"),
        "spec_nan.toml": SPEC.replace("rms_um = 10.0", "rms_um = nan"),
        "spec_ghz.toml": SPEC.replace("seed = 1", "seed = 1\nfrequencies_hz = [0.3]"),
        "spec_radiator.toml": SPEC.replace("seed = 1", 'seed = 1\nradiator = "fmm"'),
        "spec_radiator_tol.toml": SPEC.replace("seed = 1", "seed = 1\nradiator_tol = 1e-20"),
        "rig.toml": RIG,
        "rig_no_track.toml": "[limits]\nslider_min_deg = -95.0\n",
        "plan.toml": PLAN,
        "plan_noisy.toml": PLAN.replace("time_scale = 0.0", "time_scale = 0.0\nnoise_db = 0.01"),
        "plan_drift_noisy.toml": PLAN.replace("time_scale = 0.0", "time_scale = 0.0\nnoise_db = 0.01")
        .replace("reference_samples = 1", 'reference_samples = 1\ndrift_correction = "linear"')
        .replace("theta_step_deg = 20.0", "theta_step_deg = 5.0")
        .replace("phi_step_deg = 90.0", "phi_step_deg = 10.0"),
        "plan_other_dish.toml": PLAN.replace("focal_length_m = 8.0", "focal_length_m = 9.0"),
        "plan_setle.toml": PLAN.replace("samples_per_point = 1", "samples_per_point = 1\nsetle = 1.0"),
        "plan_reach.toml": PLAN.replace('rig = "rig.toml"', 'rig = "rig_short.toml"'),
        "rig_short.toml": RIG + "[limits]\nslider_max_deg = 40.0\n[park]\nslider_deg = 30.0\n",
        "rim_centre.csv": "x,y,dz\n" + "".join(
            f"{np.cos(a):.6f},{np.sin(a):.6f},0.0\n" for a in np.linspace(0, 6.0, 12)),
        "rim_header.csv": "a,b,c\n1,2,3\n",
        "rim_text.csv": "x,y,dz\n10.0,0.0,zero\n",
        "notes.txt": "a file of the user's, not a report\n",
        "probe_q.toml": SCENE + "[probe]\npolarization_deg = 0.0\npattern_q = -1.0\n",
        "probe_order.toml": SCENE + "[probe]\npattern = [[0.0, 1.0], [20.0, 0.5], [10.0, 0.2]]\n",
        "probe_angle.toml": SCENE + "[probe]\npattern = [[0.0, 1.0], [200.0, 0.5]]\n",
        "probe_both.toml": SCENE + "[probe]\npattern_q = 2.0\npattern = [[0.0, 1.0], [9.0, 0.5]]\n",
        "probe_rows.toml": SCENE + "[probe]\npattern = [1.0, 0.5]\n",
        "probe_typo.toml": SCENE + "[probe]\npolarisation_deg = 90.0\n",
        "probe_text.toml": SCENE + '[probe]\npolarization_deg = "x"\n',
        "rig_probe_q.toml": RIG + "[probe]\npattern_q = -2.0\n",
        "rig_probe_order.toml": RIG + "[probe]\npattern = [[10.0, 1.0], [5.0, 0.5]]\n",
        "rig_probe.toml": RIG + "[probe]\npolarization_deg = 0.0\n",
        "plan_probe_q.toml": PLAN.replace('rig = "rig.toml"', 'rig = "rig_probe_q.toml"'),
        "plan_probe.toml": PLAN.replace('rig = "rig.toml"', 'rig = "rig_probe.toml"'),
        "plan_obst.toml": _obstacle_plan(LEGS),
        "plan_obst_kind.toml": _obstacle_plan('type = "tower"'),
        "plan_obst_typo.toml": _obstacle_plan(LEGS + "rotation = 45.0\n"),
        "plan_obst_width.toml": _obstacle_plan(LEGS.replace("width_m = 0.3", "width_m = -0.3")),
        "plan_obst_foot.toml": _obstacle_plan(LEGS.replace("foot_radius_m = 7.0", "foot_radius_m = 12.0")),
        "plan_obst_disk.toml": _obstacle_plan('type = "disk"\nradius_m = 10.0'),
        "plan_obst_nofile.toml": _obstacle_plan('type = "mesh"\nfile = "cabin.stl"'),
        "plan_obst_noisy.toml": _obstacle_plan(LEGS, noisy=True),
        # issue 33: raysim correct
        "panel_scene.toml": _scene(PANELS.format(edges="[0.0, 5.0, 10.0]").replace(
            "panels_per_ring = [1]", "panels_per_ring = [6, 12]")),
        "panel_one.toml": _scene(PANELS.format(edges="[0.0, 10.0]")),
        "panel_other_dish.toml": _scene(PANELS.format(edges="[0.0, 5.0]"), diameter_m__20="diameter_m = 10"),
        "acts_outside.csv": "id,x_m,y_m,panels\na1,12.0,0.0,0\n",
        "acts_lonely.csv": "id,x_m,y_m,panels\na1,2.0,0.5,0\n",
        "acts_no_id.csv": "id,x_m,y_m,panels\na1,2.0,0.5,0\n,3.0,0.5,0\n",
        "acts_no_panels.csv": "id,x_m,y_m,panels\na1,2.0,0.5,0\na2,3.0,0.5,\n",
    }
    for name, text in files.items():
        (ws / name).write_text(text)
    (ws / "binary.toml").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x01\x02")
    (ws / "corrupt.nc").write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(range(200)))
    _write_mesh_in_mm(ws / "dish_mm.stl")
    save(_fieldmap(), ws / "f.nc")
    _fieldmap(lambda ideal: ideal * 1.001 - 0.01).to_netcdf(ws / "negative.nc")  # save() refuses it
    save(_fieldmap(lambda ideal: ideal * 3.7e-9), ws / "watts.nc")  # method go: the gain is trusted
    bad = _fieldmap()
    bad["intensity"].values[3, 4] = np.inf
    bad.to_netcdf(ws / "inf.nc")
    (ws / "link.nc").symlink_to(ws / "scene.toml")
    (ws / "report").mkdir()
    save(_fieldmap(), ws / "report" / "field.nc")
    (ws / "user_folder").mkdir()
    (ws / "user_folder" / "notes.txt").write_text("keep me\n")
    # a crew's own measurement under the names a run writes: replaced, exit 0, before
    (ws / "crew_folder").mkdir()
    save(_fieldmap(), ws / "crew_folder" / "surface.nc")
    (ws / "crew_check").mkdir()
    (ws / "crew_check" / "figures").mkdir()
    (ws / "crew_check" / "figures" / "fa.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    (ws / "existing_file").write_text("not a store\n")
    from solver.run import run_invert

    run_invert(ws / "f.nc", ws / "s.nc", N=32, refine=0)
    _map_in_micrometres(ws / "s.nc", ws / "s_um.nc")
    _issue_32_files(ws)  # issue 32
    return ws


def _map_in_micrometres(source: Path, path: Path) -> None:
    """``source``'s SurfaceMap with a 30 um bump stored in um as if metres (30 m)."""
    from solver import surface

    smap = surface.load(source)
    grid = surface.grid_of(smap)
    X, Y = grid.XY
    bump_um = 30.0 * np.exp(-((X - 3.0) ** 2 + Y**2) / 4.0)
    surface.save(surface.surfacemap(grid, bump_um, dict(smap.attrs)), path)


def _refused_port() -> int:
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()
    return port


NOWHERE = "TCPIP::nosuchhost.invalid::5025::SOCKET"

CASES: dict[str, list[tuple[list[str], str]]] = {
    "simulate": [
        (["simulate", "missing.toml", "-o", "o.nc"], "missing.toml: no such scene file"),
        (["simulate", "user_folder", "-o", "o.nc"], "user_folder: is a folder, give a scene file"),
        (["simulate", "scene.toml", "-o", "scene.toml"], "is the scene file"),
        (["simulate", "scene.toml", "-o", "link.nc"], "is the scene file"),
        (["simulate", "scene.toml", "-o", "sub/../scene.toml"], "is the scene file"),
        (["simulate", "mm_mesh.toml", "-o", "dish_mm.stl"], "is the file the scene names"),
        (["simulate", "scene.toml", "-o", "o.nc", "--n-theta", "abc"], "Invalid value for '--n-theta'"),
        (["simulate", "scene.toml", "-o", "o.nc", "--method", "po", "--scheduler",
          "tcp://127.0.0.1:{silent}"], "did not answer within"),
        (["simulate", "scene.toml", "-o", "o.nc", "--method", "po", "--scheduler",
          "tcp://127.0.0.1:{refused}"], "connection refused"),
        (["simulate", "scene.toml", "-o", "o.nc", "--bogus"], "No such option"),
        (["simulate", "scene.toml"], "Missing option '-o'"),
        (["simulate", "scene.toml", "-o", "o.nc", "--n-theta", "100000", "--n-phi", "100000"],
         "--n-theta must be an integer in 1..9000"),
        (["simulate", "scene.toml", "-o", "o.nc", "--n-theta", "9000", "--n-phi", "36000"],
         "cells is over the limit"),
        (["simulate", "scene.toml", "-o", "o.nc", "--method", "po", "--frequency", "inf"],
         "--frequency must be a finite frequency"),
        (["simulate", "scene.toml", "-o", "o.nc", "--frequency", "0.3"], "is in Hz"),
        (["simulate", "scene.toml", "-o", "o.nc", "--method", "po", "--frequency", "1e12"],
         "source samples per reflector"),
        (["simulate", "scene.toml", "-o", "o.nc", "--method", "magic"], "unknown method 'magic'"),
        (["simulate", "scene.toml", "-o", "o.nc", "--device", "tpu"], "unknown device 'tpu'"),
        (["simulate", "scene.toml", "-o", "o.nc", "--edges", "all"], "--edges applies to --method po+ptd"),
        (["simulate", "scene.toml", "-o", "o.nc", "--fresnel"], "--fresnel applies to --method go+edge"),
        # issue 31: the fast radiator's options
        (["simulate", "scene.toml", "-o", "o.nc", "--method", "po", "--radiator", "fmm"],
         "unknown radiator 'fmm'"),
        (["simulate", "scene.toml", "-o", "o.nc", "--method", "po", "--radiator", ""],
         "unknown radiator ''"),  # was taken as the default, fast
        (["simulate", "scene.toml", "-o", "o.nc/"], "ends in a slash"),  # wrote o.nc
        # accepted with GO and ignored before: the user believed the fast sum had run
        (["simulate", "scene.toml", "-o", "o.nc", "--radiator", "direct"],
         "--radiator and --radiator-tol apply to --method po and po+ptd only"),
        (["simulate", "scene.toml", "-o", "o.nc", "--method", "go+edge", "--radiator-tol", "1e-3"],
         "--radiator and --radiator-tol apply to --method po and po+ptd only"),
        (["simulate", "scene.toml", "-o", "o.nc", "--method", "po", "--radiator-tol", "2"],
         "--radiator-tol must lie in [1e-12, 1)"),
        # finer than float64's sums can honour: it ran (for minutes) instead of saying so
        (["simulate", "scene.toml", "-o", "o.nc", "--method", "po", "--radiator-tol", "1e-20"],
         "--radiator-tol must lie in [1e-12, 1)"),
        (["simulate", "scene.toml", "-o", "o.nc", "--method", "go+edge", "--fresnel", "--workers",
          "2"], "--fresnel runs in this process"),
        (["simulate", "scene.toml", "-o", "o.nc", "--method", "po", "--samples-per-wavelength", "-1"],
         "must lie in (0, 20]"),
        (["simulate", "scene.toml", "-o", "/proc/o.nc"], "cannot write in /proc"),
        (["simulate", "probe_q.toml", "-o", "o.nc"], "'probe': the pattern's q must be a number in 0..1000"),
        (["simulate", "probe_order.toml", "-o", "o.nc"], "angles must increase from row to row"),
        (["simulate", "probe_angle.toml", "-o", "o.nc"], "angles must lie in 0..180 deg, got 0..200"),
        (["simulate", "probe_both.toml", "-o", "o.nc"], "(cos^q) or 'probe.pattern' (a table), not both"),
        (["simulate", "probe_rows.toml", "-o", "o.nc"], "must be a list of [angle_deg, relative_power] rows"),
        (["simulate", "probe_typo.toml", "-o", "o.nc"], "unknown key 'probe.polarisation_deg'"),
        (["simulate", "probe_text.toml", "-o", "o.nc"], "'probe.polarization_deg' must be a number"),
        (["simulate", "binary.toml", "-o", "o.nc"], "not a text file"),
        (["simulate", "bad_toml.toml", "-o", "o.nc"], "not valid TOML"),
        (["simulate", "typo.toml", "-o", "o.nc"], "unknown key 'dish.diametre_m' (did you mean 'diameter_m'?)"),
        (["simulate", "no_edges.toml", "-o", "o.nc"], "'panels.ring_edges_m' needs at least 2"),
        (["simulate", "obst_kind.toml", "-o", "o.nc"], "'obstacle[0].type' must be one of disk, legs, mesh"),
        (["simulate", "obst_width.toml", "-o", "o.nc"], "'obstacle[0].width_m' must be > 0"),
        (["simulate", "obst_count.toml", "-o", "o.nc"], "'obstacle[0].count' must be >= 1"),
        (["simulate", "obst_mm.toml", "-o", "o.nc"], "is it in mm?"),
        (["simulate", "obst_foot.toml", "-o", "o.nc"], "is beyond the rim"),
        (["simulate", "obst_apex.toml", "-o", "o.nc"], "is not above the feet"),
        (["simulate", "obst_typo.toml", "-o", "o.nc"], "did you mean 'rotation_deg'?"),
        (["simulate", "obst_disk.toml", "-o", "o.nc"], "covers the whole dish"),
        (["simulate", "obst_nofile.toml", "-o", "o.nc"], "'obstacle[0].file': no such file"),
        (["simulate", "obst_junk.toml", "-o", "o.nc"], "trimesh cannot read the obstacle mesh"),
        (["simulate", "nan_edge.toml", "-o", "o.nc"], "'panels.ring_edges_m' must hold finite numbers"),
        (["simulate", "zernike_nan.toml", "-o", "o.nc"], "must be a finite number"),
        (["simulate", "paper_huge.toml", "-o", "o.nc"], "scale' = 1e+07 makes a"),
        (["simulate", "fine_mesh.toml", "-o", "o.nc"], "million triangles"),
        (["simulate", "units_um.toml", "-o", "o.nc"], "dz must be in metres"),
        (["simulate", "text_cell.toml", "-o", "o.nc"], "is not all numbers"),
        (["simulate", "inf_cell.toml", "-o", "o.nc"], "infinite value"),
        (["simulate", "nan_x.toml", "-o", "o.nc"], "x and y must be finite numbers"),
        (["simulate", "corrupt_map.toml", "-o", "o.nc"], "not a readable NetCDF file"),
        (["simulate", "mm_mesh.toml", "-o", "o.nc"], "is the file in mm?"),
        (["simulate", "big_sphere.toml", "-o", "o.nc"], "'sphere.n_theta' must be an integer in 1..9000"),
        (["simulate", "method_bad.toml", "-o", "o.nc"], "'method' must be one of go, po, po+ptd"),
    ],
    "invert": [
        (["invert", "missing.nc", "-o", "o.nc"], "missing.nc: no such file"),
        (["invert", "f.nc", "-o", "f.nc"], "is the FieldMap"),
        (["invert", "f.nc", "-o", "./sub/../f.nc"], "is the FieldMap"),
        (["invert", "f.nc", "-o", "o.nc", "--grid", "100000"], "--grid) must be an integer in 16..4096"),
        (["invert", "f.nc", "-o", "o.nc", "--grid", "8"], "must be an integer in 16..4096"),
        (["invert", "f.nc", "-o", "o.nc", "--grid", "abc"], "Invalid value for '--grid'"),
        (["invert", "f.nc", "-o", "o.nc", "--refine", "-1"], "--refine) must be an integer in 0..50"),
        (["invert", "f.nc", "-o", "o.nc", "--solver", "magic"], "unknown solver 'magic'"),
        (["invert", "f.nc", "-o", "o.nc", "--remove", "bogus"], "unknown term 'bogus'"),
        (["invert", "f.nc", "-o", "o.nc", "--gain", "maybe"], "unknown gain mode"),
        (["invert", "f.nc", "-o", "o.nc", "--model", "ray"], "unknown model 'ray'"),
        (["invert", "f.nc", "-o", "o.nc", "--gn-steps", "0"], "Gauss-Newton steps must be an integer in 1..50"),
        (["invert", "f.nc", "-o", "o.nc", "--gn-lsqr", "5000"],
         "LSQR iterations per step must be an integer in 1..1000"),
        (["invert", "corrupt.nc", "-o", "o.nc"], "not a readable NetCDF file"),
        (["invert", "negative.nc", "-o", "o.nc"], "holds negative values"),
        (["invert", "inf.nc", "-o", "o.nc"], "holds infinite values"),
        (["invert", "watts.nc", "-o", "o.nc"], "holds 3.7e-09 times the ideal's total power"),
        (["invert", "f.nc", "-o", "o.nc", "--rim", "rim_centre.csv"], "must lie near the rim"),
        (["invert", "f.nc", "-o", "o.nc", "--rim", "rim_header.csv"], "header x,y,dz"),
        (["invert", "f.nc", "-o", "o.nc", "--rim", "rim_text.csv"], "row 2 is not three numbers"),
        (["invert", "f.nc", "-o", "rim_centre.csv", "--rim", "rim_centre.csv"], "is the rim-target file"),
        (["invert", "f.nc", "-o", "o.nc", "--panels-csv", "f.nc"], "is the FieldMap"),
        # issue 31: the fast radiator's options on the refinement's model
        (["invert", "f.nc", "-o", "o.nc", "--radiator", "fmm"], "unknown radiator 'fmm'"),
        (["invert", "f.nc", "-o", "o.nc", "--radiator-tol", "0"], "--radiator-tol must lie in [1e-12, 1)"),
        (["invert", "f.nc", "-o", "o.nc/"], "ends in a slash"),
        # accepted with a GO model and ignored before (simulate refused the same pairing)
        (["invert", "f.nc", "-o", "o.nc", "--radiator", "direct"], "apply to a po or po+ptd refinement model"),
        (["invert", "f.nc", "-o", "o.nc", "--model", "po", "--refine", "0", "--radiator-tol", "1e-3"],
         "this run's model is none (--refine 0)"),
        (["invert", "f.nc", "-o", "o.nc", "--radiator-tol", "1e-13"], "--radiator-tol must lie in [1e-12, 1)"),
    ],
    "render": [
        (["render", "missing.nc", "-o", "o.png"], "missing.nc"),
        (["render", "f.nc", "-o", "f.nc"], "is the file to draw"),
        (["render", "f.nc", "-o", "o.png", "--kind", "bogus"], "bogus"),
        (["render", "f.nc", "-o", "o.png", "--size", "10x"], "--size"),
        (["render", "f.nc", "-o", "o.png", "--quantity", "foo"], "foo"),
        (["render", "corrupt.nc", "-o", "o.png"], "not a readable NetCDF file"),
        (["render", "scene.toml", "-o", "o.png"], "scene.toml"),
        (["render", "s.nc", "-o", "/proc/o.png"], "cannot write in /proc"),
        (["render", "s.nc", "-o", "s.nc"], "is the file to draw"),
    ],
    "report": [
        (["report", "scene.toml", "-o", "rep_new", "--solver", "magic"], "unknown solver 'magic'"),
        (["report", "scene.toml", "-o", "rep_new", "--grid", "100000"], "must be an integer in 16..4096"),
        (["report", "scene.toml", "-o", "rep_new", "--refine", "99"], "must be an integer in 0..50"),
        (["report", "scene.toml", "-o", "rep_new", "--method", "magic"], "unknown method 'magic'"),
        (["report", "report/field.nc", "-o", "report"], "holds the FieldMap"),
        (["report", "f.nc", "-o", "user_folder"], "holds files that are not a raysim report"),
        (["report", "f.nc", "-o", "crew_folder"], "holds surface.nc but no report.html"),
        (["report", "f.nc", "-o", "notes.txt"], "exists and is not a folder"),
        (["report", "f.nc", "-o", "notes.txt/rep"], "notes.txt is a file, not a folder"),
        (["report", "user_folder", "-o", "rep_new"], "is a folder, give a scene file or a FieldMap"),
        (["report", "f.nc", "-o", "/proc/rep"], "cannot write in /proc"),  # before the work
        (["report", "missing.toml", "-o", "rep_new"], "no such scene file"),
        (["report", "corrupt.nc", "-o", "rep_new"], "not a readable NetCDF file"),
    ],
    "check": [
        (["check", "scene.toml", "-o", "rep_new", "--frequency", "0"], "must be a finite frequency > 0 Hz"),
        (["check", "scene.toml", "-o", "rep_new", "--frequency", "-1e9"], "must be a finite frequency"),
        (["check", "scene.toml", "-o", "rep_new", "--gap-m", "5"], "wider than a panel allows"),
        (["check", "scene.toml", "-o", "rep_new", "--wave", "fdtd"], "unknown --wave 'fdtd'"),
        (["check", "scene.toml", "-o", "rep_new", "--json", "rep_new/check.nc"],
         "lies in the check's output folder"),
        (["check", "scene.toml", "-o", "rep_new", "--refine-model", "x"], "unknown --refine-model 'x'"),
        (["check", "scene.toml", "-o", "rep_new", "--sphere", "9x"], "--sphere takes"),
        (["check", "dish_mm.stl", "-o", "rep_new", "--frequency", "1e9"], "then give --mesh-unit 0.001"),
        (["check", "dish_mm.stl", "-o", "rep_new", "--frequency", "1e9", "--mesh-unit", "-1"],
         "--mesh-unit must be metres per file unit > 0"),
        (["check", "scene.toml", "-o", "rep_new", "--mesh-unit", "0.001"], "apply to a mesh file"),
        (["check", "scene.toml", "-o", "user_folder"], "holds files that are not a raysim check"),
        (["check", "scene.toml", "-o", "crew_check"], "holds figures but no check.html"),
        (["check", "scene.toml", "-o", "notes.txt"], "exists and is not a folder"),
        (["check", "scene.toml", "-o", "/proc/chk"], "cannot write in /proc"),
        # issue 31: the fast radiator's options
        (["check", "scene.toml", "-o", "rep_new", "--radiator", "fmm"], "unknown radiator 'fmm'"),
        (["check", "scene.toml", "-o", "rep_new", "--radiator-tol", "1.5"], "--radiator-tol must lie in [1e-12, 1)"),
    ],
    "paper": [
        (["paper", "--scale", "1e7"], "--scale must lie in (0, 50]"),
        (["paper", "--po", "--radiator", "fmm"], "unknown radiator 'fmm'"),  # issue 31
        (["paper", "--scale", "nan"], "--scale must lie in (0, 50]"),
        (["paper", "--grid", "3"], "must be an integer in 16..4096"),
        (["paper", "--po", "--frequencies", "inf"], "--frequencies must be a finite frequency"),
        (["paper", "--po", "--frequencies", "abc"], "--frequencies takes frequencies in Hz"),
        (["paper", "--po", "--frequencies", "1e12"], "above the sweep's"),
        (["paper", "--po", "--coarse-3ghz", "9x"], "--coarse-3ghz takes a sphere grid"),
        (["paper", "--po", "--wave-max-ghz", "nan"], "--wave-max-ghz must be a finite number"),
    ],
    "dataset": [
        (["dataset", "missing.toml", "-o", "d.zarr"], "no such dataset spec file"),
        (["dataset", "spec.toml", "-o", "/proc/d.zarr"], "cannot write in /proc"),
        (["dataset", "spec_typo.toml", "-o", "d.zarr"], "unknown key 'sede' (did you mean 'seed'?)"),
        (["dataset", "spec_nan.toml", "-o", "d.zarr"], "'errors[0].rms_um' must be a finite number"),
        (["dataset", "spec_ghz.toml", "-o", "d.zarr"], "in Hz, not GHz"),
        (["dataset", "spec_obstacles.toml", "-o", "d.zarr"], "has [[obstacle]] tables"),
        (["dataset", "spec.toml", "-o", "d.zarr", "--scheduler", "notanaddress"], "tcp://HOST:PORT"),
        (["dataset", "spec.toml", "-o", "d.zarr", "--scheduler", "tcp://127.0.0.1:{silent}"],
         "did not answer within"),
        (["dataset", "spec.toml", "-o", "d.zarr", "--workers", "0"], "--workers must be an integer"),
        (["dataset", "spec.toml", "-o", "d.zarr", "--threads", "0"], "--threads must be an integer"),
        (["dataset", "spec.toml", "-o", "existing_file", "--resume"], "is not a Zarr store"),
        (["dataset", "spec.toml", "-o", "spec.toml", "--resume"], "is the dataset spec"),
        (["dataset", "spec.toml", "-o", "d.zarr", "--device", "tpu"], "unknown device 'tpu'"),
        # issue 31: the spec's radiator
        (["dataset", "spec_radiator.toml", "-o", "d.zarr"], "'radiator' must be one of"),
        (["dataset", "spec_radiator_tol.toml", "-o", "d.zarr"], "'radiator_tol' must be >= 1e-12"),
    ],
    "scan": [
        (["scan", "missing.toml", "-o", "o.nc", "--simulate", "f.nc"], "no such scan plan file"),
        (["scan", "plan_setle.toml", "-o", "o.nc", "--simulate", "f.nc"],
         "unknown key 'acquisition.setle' (did you mean 'settle_s'?)"),
        (["scan", "plan_reach.toml", "-o", "o.nc", "--simulate", "f.nc"], "(see [limits] in the rig file)"),
        (["scan", "plan.toml", "-o", "f.nc", "--simulate", "f.nc"], "is the FieldMap the simulated rig scans"),
        (["scan", "plan.toml", "-o", "x.nc", "--journal", "x.nc", "--simulate", "f.nc"], "is the journal"),
        (["scan", "plan.toml", "-o", "plan.toml", "--simulate", "f.nc"], "is the plan or rig file"),
        (["scan", "plan.toml", "-o", "o.nc", "--journal", "rig.toml", "--simulate", "f.nc"],
         "is the plan or rig file"),
        (["scan", "plan.toml", "-o", "o.nc", "--simulate", "f.nc", "--seed", "-1"], "seed"),
        (["scan", "plan.toml", "-o", "o.nc", "--simulate", "f.nc", "--noise-db", "20"],
         "noise_db (--noise-db, [simulator] noise_db) must be a number in 0..10"),
        (["scan", "plan.toml", "-o", "o.nc", "--simulate", "f.nc", "--centre-offset", "1,2"],
         "give three numbers"),
        (["scan", "plan.toml", "-o", "o.nc", "--simulate", "f.nc", "--resource", f"meter={NOWHERE}"],
         "not both"),
        (["scan", "plan.toml", "-o", "o.nc", "--resource", "bogus"], "write ROLE=VISA"),
        (["scan", "plan.toml", "-o", "o.nc", "--noise-db", "0.1"], "apply with --simulate only"),
        (["scan", "plan.toml", "-o", "o.nc", "--resource", f"meter={NOWHERE}",
          "--resource", f"motion={NOWHERE}"], "unknown host 'nosuchhost.invalid'"),
        (["scan", "plan.toml", "-o", "o.nc", "--resource", "meter=TCPIP::127.0.0.1::{refused}::SOCKET",
          "--resource", "motion=TCPIP::127.0.0.1::{refused}::SOCKET"], "is unreachable"),
        (["scan", "plan.toml", "-o", "o.nc", "--resource", "meter=TCPIP::127.0.0.1::{silent}::SOCKET",
          "--resource", "motion=TCPIP::127.0.0.1::{silent}::SOCKET"], "is silent"),
        (["scan", "plan.toml", "-o", "o.nc", "--simulate", "negative.nc"], "holds negative values"),
        (["scan", "plan_probe_q.toml", "-o", "o.nc", "--simulate", "f.nc"], "pattern's q must be"),
        (["scan", "plan_obst_kind.toml", "-o", "o.nc", "--simulate", "f.nc"],
         "'obstacle[0].type' must be one of disk, legs, mesh"),
        (["scan", "plan_obst_typo.toml", "-o", "o.nc", "--simulate", "f.nc"], "did you mean 'rotation_deg'?"),
        (["scan", "plan_obst_foot.toml", "-o", "o.nc", "--simulate", "f.nc"], "is beyond the rim"),
        (["scan", "plan_obst_nofile.toml", "-o", "o.nc", "--simulate", "f.nc"],
         "'obstacle[0].file': no such file"),
        (["scan", "plan_obst.toml", "-o", "o.nc", "--simulate", "f.nc"], "has no obstacles in the beam"),
        (["scan", "plan_probe.toml", "-o", "o.nc", "--simulate", "f.nc"],
         "was simulated with the probe 'ideal |E|^2 power meter', the rig has 'polarised at 0 deg"),
    ],
    "budget": [
        (["budget", "missing.toml"], "no such scan plan file"),
        (["budget", "user_folder"], "is a folder, give a scan plan file"),
        (["correct", "user_folder", "-o", "corr"], "is a folder, give a NetCDF file"),
        (["budget", "plan_setle.toml"], "unknown key 'acquisition.setle'"),
        (["budget", "plan.toml"], "fewer than four theta rows inside the rim image"),
        (["budget", "plan.toml", "--noise-db", "abc"], "must be numbers separated by commas"),
        (["budget", "plan.toml", "--noise-db", "0.01,0"], "must lie in (0, 10] dB"),
        (["budget", "plan.toml", "--readings", "0"], "--readings must be an integer in 1..100000"),
        (["budget", "plan.toml", "--rim", "3"], "at least 8 targets"),
        (["budget", "plan.toml", "--rim-std-um", "-1"], "--rim-std-um must lie in 0..10000 um"),
        (["budget", "plan.toml", "--target-um", "0"], "--target-um must lie in (0, 10000] um"),
        (["budget", "plan.toml", "--gain", "maybe"], "unknown gain 'maybe'"),
        (["budget", "plan.toml", "--refine", "-2"], "--refine must be an integer in 0..50"),
        (["budget", "plan.toml", "--remove", "astigmatism"], "unknown term 'astigmatism' to remove"),
        (["budget", "plan_obst_width.toml"], "'obstacle[0].width_m' must be > 0"),
        (["budget", "plan_obst_disk.toml"], "covers the whole dish"),
    ],
    "campaign": [
        (["campaign", "missing.toml", "plan_noisy.toml", "-o", "c"], "no such scene file"),
        (["campaign", "scene.toml", "plan_noisy.toml", "-o", "crew_folder"],
         "holds surface.nc but no campaign.txt, so it is not a raysim campaign's folder"),
        (["campaign", "scene.toml", "missing.toml", "-o", "c"], "no such scan plan file"),
        (["campaign", "scene.toml", "plan.toml", "-o", "c"], "noise_db must be above 0"),
        (["campaign", "scene.toml", "plan_other_dish.toml", "-o", "c"], "is not the scene's dish"),
        (["campaign", "scene.toml", "plan_obst_typo.toml", "-o", "c"], "did you mean 'rotation_deg'?"),
        (["campaign", "scene.toml", "plan_obst_noisy.toml", "-o", "c"],
         "the plan's obstacles (4 legs 0.3 m wide"),
        (["campaign", "scene.toml", "plan_noisy.toml", "-o", "c", "--readings", "2",
          "--target-um", "20"], "not both"),
        (["campaign", "scene.toml", "plan_noisy.toml", "-o", "notes.txt"], "is not a folder"),
        (["campaign", "scene.toml", "plan_noisy.toml", "-o", "c", "--grid", "8"],
         "must be an integer in 16..4096"),
        (["campaign", "scene.toml", "plan_noisy.toml", "-o", "c", "--rim", "3"],
         "at least 8 targets"),
        (["campaign", "scene.toml", "plan_drift_noisy.toml", "-o", "c", "--rim", "0",
          "--target-um", "0.001"], "out of reach at any readings per point"),
    ],
    # issue 33: raysim correct
    "correct": [
        (["correct", "missing.nc", "-o", "corr", "--scene", "panel_scene.toml"], "missing.nc"),
        (["correct", "s.nc", "-o", "corr"], "no panel layout"),
        (["correct", "s.nc", "-o", "corr", "--scene", "scene.toml"], "no panel layout"),
        (["correct", "s.nc", "-o", "corr", "--scene", "panel_other_dish.toml"],
         "the map is of a 20 m dish, the panel layout of a 10 m one"),
        (["correct", "s.nc", "-o", "corr", "--scene", "panel_scene.toml", "--actuators",
          "acts_outside.csv", "--stroke", "1e-5"], "--stroke bounds generated layouts"),
        (["correct", "s.nc", "-o", "corr", "--scene", "panel_scene.toml", "--actuators",
          "acts_outside.csv"], "lies outside the dish"),
        (["correct", "s.nc", "-o", "corr", "--scene", "panel_scene.toml", "--actuators",
          "acts_lonely.csv"], "panel 1 is held by no actuator"),
        (["correct", "s.nc", "-o", "corr", "--scene", "panel_one.toml"], "has no corners"),
        (["correct", "s.nc", "-o", "corr", "--scene", "panel_scene.toml", "--layout", "hexes"],
         "unknown --layout 'hexes'"),
        (["correct", "s.nc", "-o", "corr", "--scene", "panel_scene.toml", "--unit", "inch"],
         "unknown --unit 'inch'"),
        (["correct", "s.nc", "-o", "corr", "--scene", "panel_scene.toml", "--frequency", "-1"],
         "--frequency must be a finite frequency > 0 Hz"),
        (["correct", "s.nc", "-o", "corr", "--scene", "panel_scene.toml", "--frequency", "inf"],
         "--frequency must be a finite frequency > 0 Hz"),
        (["correct", "s.nc", "-o", "corr", "--scene", "panel_scene.toml", "--frequency", "43"],
         "--frequency = 43 is in Hz"),
        (["correct", "s.nc", "-o", "notes.txt", "--scene", "panel_scene.toml"], "give a folder"),
        (["correct", "s.nc", "-o", "corr", "--scene", "panel_scene.toml", "--remove", "coma"],
         "unknown term 'coma'"),
        (["correct", "s_um.nc", "-o", "corr", "--scene", "panel_scene.toml"],
         "s_um.nc: the map departs by up to"),
        (["correct", "s.nc", "-o", "corr", "--scene", "panel_scene.toml", "--actuators",
          "acts_no_id.csv"], "acts_no_id.csv: actuator row 2: its id is empty"),
        (["correct", "s.nc", "-o", "corr", "--scene", "panel_scene.toml", "--actuators",
          "acts_no_panels.csv"], "acts_no_panels.csv: actuator row 2 (actuator a2): its panels are empty"),
    ],
    "rig park": [
        (["rig", "park", "missing.toml", "--simulate"], "no such rig file"),
        (["rig", "park", "rig_no_track.toml", "--simulate"], "missing table [track]"),
        (["rig", "park", "rig.toml", "--simulate", "--resource", f"motion={NOWHERE}"], "not both"),
        (["rig", "park", "rig.toml", "--resource", f"meter={NOWHERE}"],
         "drives the motion controller only"),
        (["rig", "park", "rig.toml", "--resource", f"motion={NOWHERE}"], "unknown host"),
        (["rig", "park", "rig.toml", "--resource", "motion=TCPIP::127.0.0.1::{refused}::SOCKET"],
         "is unreachable"),
        (["rig", "park", "rig.toml", "--resource", "motion=TCPIP::127.0.0.1::{silent}::SOCKET"],
         "is silent"),
        (["rig", "park", "rig.toml"], "no motion controller address"),
        (["rig", "park", "rig.toml", "--speed", "3"], "No such option"),
        (["rig", "park", "rig_probe_order.toml", "--simulate"], "angles must increase from row to row"),
    ],
    # issue 34: --json of the table-printing commands refuses an input, a folder or a place
    # where nothing can be written, before any work
    "--json (issue 34)": [
        (["budget", "plan.toml", "--json", "plan.toml"], "is the plan"),
        (["budget", "plan.toml", "--json", "rig.toml"], "is the plan or rig file"),
        (["budget", "plan.toml", "--json", "."], "is a folder, give a file name"),
        (["check", "scene.toml", "-o", "rep_new", "--json", "scene.toml"], "is the source"),
        (["check", "scene.toml", "-o", "rep_new", "--json", "user_folder"], "is a folder"),
        (["paper", "--json", "/proc/raysim.json"], "cannot write in /proc"),
    ],
}


# --- issue 32: sizes without limits, nonsense read back from files, counts of 0 ---------------
def _issue_32_files(ws: Path) -> None:
    """The inputs of the issue-32 rows: a TOML nested 1000 deep, an STL with a NaN vertex (and
    a scene naming it), FieldMaps whose attributes lie, plans too fine or at 1e30 Hz."""
    import trimesh

    from raysim.surface.mesh import paraboloid

    (ws / "deep.toml").write_text("a = " + "[" * 1000 + "]" * 1000 + "\n")
    dish = paraboloid(D, F, 2.0)
    vertices = np.array(dish.vertices, dtype=np.float64)
    vertices[len(vertices) // 2] = np.nan
    trimesh.Trimesh(vertices, dish.faces, process=False).export(ws / "nan.stl")
    (ws / "nan_mesh.toml").write_text(SCENE.replace("diameter_m = 20.0\nfocal_length_m = 8.0",
                                                    'focal_length_m = 8.0\nmesh = "nan.stl"'))
    for name, key, value in (("f_thz.nc", "frequency_hz", 1e13), ("f_1e30.nc", "frequency_hz", 1e30),
                             ("f_magic.nc", "method", "magic")):
        ds = _fieldmap()
        ds.attrs[key] = value
        ds.to_netcdf(ws / name)  # save() would refuse them
    (ws / "plan_fine.toml").write_text(PLAN.replace("theta_step_deg = 20.0", "theta_step_deg = 0.001")
                                       .replace("phi_step_deg = 90.0", "phi_step_deg = 0.001"))
    (ws / "plan_1e30.toml").write_text(PLAN.replace("frequency_hz = 1.0e9", "frequency_hz = 1.0e30"))


ISSUE_32: dict[str, list[tuple[list[str], str]]] = {
    "simulate": [
        (["simulate", "scene.toml", "-o", "o.nc", "--workers", "0"],
         "--workers must be an integer in 1..1024, got 0"),
        (["simulate", "scene.toml", "-o", "o.nc", "--workers", "1", "--threads", "0"],
         "--threads must be an integer in 1..256, got 0"),
        (["simulate", "deep.toml", "-o", "o.nc"], "deep.toml: nested too deeply"),
        (["simulate", "nan_mesh.toml", "-o", "o.nc"], "nan.stl: holds vertices that are not finite"),
    ],
    "invert": [
        (["invert", "f_thz.nc", "-o", "o.nc", "--model", "po"], "source samples per reflector"),
        (["invert", "f_thz.nc", "-o", "o.nc", "--model", "go+edge"], "source samples per reflector"),
        (["invert", "f_1e30.nc", "-o", "o.nc"], "'frequency_hz' = 1e+30 Hz is outside"),
        (["invert", "f_magic.nc", "-o", "o.nc"], "attribute 'method' must be one of"),
    ],
    "render": [
        (["render", "f_magic.nc", "-o", "o.png"], "attribute 'method' must be one of"),
    ],
    "report": [
        (["report", "f_1e30.nc", "-o", "rep_new"], "is outside 1e+06 .. 1e+13 Hz"),
    ],
    "check": [
        (["check", "scene.toml", "-o", "rep_new", "--gap-m", "-0.01"],
         "--gap-m must be a finite width >= 0 m, got -0.01"),
        (["check", "nan.stl", "-o", "rep_new", "--frequency", "1e9"], "holds vertices that are not finite"),
    ],
    "dataset": [
        (["dataset", "deep.toml", "-o", "d.zarr"], "nested too deeply"),
    ],
    "scan": [
        (["scan", "plan_fine.toml", "-o", "o.nc", "--simulate", "f.nc"],
         "'grid' theta cells must be an integer in 1..9000"),
        (["scan", "plan_1e30.toml", "-o", "o.nc", "--simulate", "f.nc"], "'reflector.frequency_hz' = 1e+30"),
    ],
    "budget": [
        (["budget", "plan_fine.toml"], "'grid' theta cells must be an integer in 1..9000"),
        (["budget", "plan_1e30.toml"], "'reflector.frequency_hz' = 1e+30"),
    ],
    "campaign": [
        (["campaign", "scene.toml", "plan_fine.toml", "-o", "c"], "'grid' theta cells must be an integer"),
    ],
}
for _command, _rows in ISSUE_32.items():
    CASES[_command].extend(_rows)
# --- end of issue 32 -----------------------------------------------------------------------------


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file() and not p.is_symlink()}


def test_the_table_covers_every_command():
    counts = {name: len(cases) for name, cases in CASES.items()}
    assert sum(counts.values()) >= 60 and min(counts.values()) >= 5, counts


@pytest.mark.parametrize(("args", "message"),
                         [pytest.param(a, m, id=f"{name}-{i}") for name, cases in CASES.items()
                          for i, (a, m) in enumerate(cases)])
def test_bad_input_is_one_line_status_2_and_touches_nothing(workspace, raysim_cli, monkeypatch,
                                                            args, message):
    from raysim.distributed import cluster

    monkeypatch.chdir(workspace)
    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT_S", 2.0)
    silent, stop = _silent_server()
    try:
        ports = {"silent": silent, "refused": _refused_port()}
        argv = [a.format(**ports) for a in args]
        before = _snapshot(workspace)
        result = raysim_cli(*argv)
    finally:
        stop.set()
    assert result.code == 2, (result.code, result.stdout, result.stderr)
    line = result.error()
    assert "Traceback" not in result.stderr
    assert line.startswith("error: "), line
    assert message in line, line
    after = _snapshot(workspace)
    assert {name: after.get(name) for name in before} == before
    assert not os.path.exists(workspace / "o.nc") and not os.path.exists(workspace / "rep_new")
