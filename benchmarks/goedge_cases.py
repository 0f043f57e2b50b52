"""The cases of the go+edge benchmark and their PO + PTD reference FieldMaps (cached).

Each reference is run once with ``po+ptd`` (complex fields saved) and kept under the ignored
``out/goedge_ref/`` folder; later runs read it back. The paper-dish files carry the names the
Table 3 sweep of ``raysim paper --po --fields DIR`` reuses.

Run: ``nice -n 10 .venv/bin/python benchmarks/goedge_cases.py [CASE ...]`` (default: all, in
the order below, cheapest first).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
REF_DIR = ROOT / "out" / "goedge_ref"

_DISH = """
name = "{name}"
description = "{text}, E along x, Eq. 8 deformation for its D and F"
[dish]
diameter_m = {D}
focal_length_m = {F}
resolution_m = {faces}
[[deformation]]
type = "paper"
scale = 1.0
[source]
frequency_hz = {{f}}
polarization_deg = 0.0
[sphere]
radius_m = {R}
n_theta = {{n_theta}}
n_phi = {{n_phi}}
"""
PAPER = _DISH.format(name="paper_po_table3", text="Paper Table 3: D = 110 m, F = 33 m, R = 10 m",
                     D=110.0, F=33.0, faces=5.0, R=10.0)
# a 25 m dish with the paper's F / D and R / F, the Eq. 8 shape at its own scale (D, F)
DISH25 = _DISH.format(name="dish25", text="25 m dish, F = 7.5 m, R = 2.5 m", D=25.0, F=7.5,
                      faces=1.25, R=2.5)


@dataclass(frozen=True)
class Case:
    """One comparison: a scene text, a frequency and grid, the edge set of the reference."""

    name: str
    template: str
    frequency_hz: float
    n_theta: int = 90
    n_phi: int = 360
    edges: str = "rim"
    phi_max_deg: float | None = None  # a sector of the sphere (phi from 0)

    def scene(self):
        from raysim.scene.scene import load_scene, parse_scene

        if self.template == "panels":
            text = load_scene(ROOT / "scenes" / "panels_ptd.toml").text.replace(
                "frequency_hz = 0.3e9", f"frequency_hz = {self.frequency_hz}")
        else:
            text = self.template.format(f=self.frequency_hz, n_theta=self.n_theta, n_phi=self.n_phi)
        if self.phi_max_deg is not None:
            text = text.replace("n_phi = 360", f"n_phi = {self.n_phi}").replace(
                f"n_phi = {self.n_phi}", f"n_phi = {self.n_phi}\nphi_max_deg = {self.phi_max_deg}")
        return parse_scene(text, source=self.name, base=ROOT / "scenes")

    @property
    def path(self) -> Path:
        if self.template is PAPER and self.phi_max_deg is None:
            return REF_DIR / f"paper_poptd_{self.frequency_hz / 1e9:g}GHz_{self.n_theta}x{self.n_phi}.nc"
        return REF_DIR / f"{self.name}_poptd_{self.n_theta}x{self.n_phi}.nc"


CASES = {c.name: c for c in (
    Case("paper_0.3GHz", PAPER, 0.3e9),
    Case("dish25_1GHz", DISH25, 1e9),
    Case("paper_1GHz", PAPER, 1e9),
    Case("paper_3GHz", PAPER, 3e9, 90, 36),
    Case("paper_3GHz_full", PAPER, 3e9, 90, 360),  # the fast radiator's reach (issue 31)
    Case("paper_6GHz_full", PAPER, 6e9, 90, 360),
    Case("paper_12GHz_full", PAPER, 12e9, 90, 360),  # the elements summed in batches
    Case("dish25_3GHz", DISH25, 3e9),
    Case("panels_3GHz", "panels", 3e9, 90, 60, edges="all", phi_max_deg=60.0),
    # the field's mirror symmetries in x and y (axisymmetric dish and shape, E along x): the
    # quadrant phi 0..90 deg at the full grid's 1 deg cells holds the whole sphere's map
    Case("dish25_10GHz", DISH25, 10e9, 90, 90, phi_max_deg=90.0),
    Case("paper_1GHz_quadrant", PAPER, 1e9, 90, 90, phi_max_deg=90.0),
)}


def reference(case: Case, log=print):
    """The PO + PTD FieldMap of ``case``: read from the cache, else simulated and cached."""
    from raysim.maps.fieldmap import load, save
    from raysim.simulate import simulate

    if case.path.is_file():
        return load(case.path)
    start = time.perf_counter()
    log(f"{case.name}: PO + PTD ({case.edges}) on {case.n_theta} x {case.n_phi} ...")
    ds = simulate(case.scene(), method="po+ptd", edges=case.edges, save_field=True)
    case.path.parent.mkdir(parents=True, exist_ok=True)
    save(ds, case.path)
    log(f"{case.name}: {time.perf_counter() - start:.0f} s -> {case.path}")
    return ds


if __name__ == "__main__":
    names = sys.argv[1:] or list(CASES)
    for name in names:
        reference(CASES[name], log=lambda line: print(time.strftime("%H:%M:%S"), line, flush=True))
