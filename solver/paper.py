"""The paper's GO case (PAPER.tex Table 2 conditions) run with the project's own GO forward model.

D = 110 m, F = 33 m, R = 10 m, 90 x 360 one-degree cells, the Eq. 8 deformation (peak-to-peak
1.2 mm at scale 1). The paper's figures (GO data): FDM + Gauss-Seidel with 1000 iterations at
N = 256, RRMS 4.06 % in 92 +- 10 s; FFT, RRMS 7.47 %. raysim's rows use the same data and grid.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import xarray as xr

from raysim.field import fieldmap
from raysim.sphere import SphereGrid
from solver.invert import DEFAULT_REFINE, DEFAULT_SOLVER, invert

D, F, R = 110.0, 33.0, 10.0
FREQUENCY_HZ = 0.3e9


@dataclass
class Row:
    """One line of the comparison: method, the paper's RRMS and time, ours."""

    method: str
    paper_rrms: float | None
    paper_seconds: str
    rrms: float
    rms_m: float
    seconds: float


def paper_fieldmap(scale: float = 1.0, device: str | None = "cpu") -> xr.Dataset:
    """GO FieldMap of the paper's case from the project's engine (Eq. 8 times ``scale``)."""
    from raysim.deformation import PaperDeformation
    from raysim.go import forward_intensity

    grid = SphereGrid(R, 90, 360)
    ideal = forward_intensity(grid, F, D, None, device=device)
    deformed = forward_intensity(grid, F, D, PaperDeformation(D, F, scale), device=device)
    return fieldmap(grid, deformed, ideal, focal_length=F, diameter=D, frequency_hz=FREQUENCY_HZ,
                    method="go", sampling="cell_mean",
                    attrs={"deformation": f"paper Eq. 8 x {scale:g}"})


def compare(scale: float = 1.0, N: int = 256, refine: int = DEFAULT_REFINE,
            device: str | None = "cpu", field: xr.Dataset | None = None) -> list[Row]:
    """The paper's GO rows beside ours on the same data; RRMS against Eq. 8 times ``scale``."""
    from raysim.deformation import PaperDeformation

    field = paper_fieldmap(scale, device) if field is None else field
    truth = PaperDeformation(D, F, scale)
    runs = [
        ("FDM + Gauss-Seidel, 1000 iterations", 0.0406 if scale == 1.0 else None,
         "92 +- 10" if scale == 1.0 else "-",
         {"solver": "gauss-seidel", "iterations": 1000, "refine_iterations": 0}),
        ("FFT (enclosing square)", 0.0747 if scale == 1.0 else None, "-",
         {"solver": "fft", "refine_iterations": 0}),
        (f"raysim linear ({DEFAULT_SOLVER}, refine 0)", None, "-",
         {"solver": DEFAULT_SOLVER, "refine_iterations": 0}),
        (f"raysim default ({DEFAULT_SOLVER}, GO refine {refine})", None, "-",
         {"solver": DEFAULT_SOLVER, "refine_iterations": refine}),
    ]
    rows = []
    for method, paper_rrms, paper_seconds, options in runs:
        start = time.perf_counter()
        result = invert(field, N=N, truth=truth, device=device, **options)
        rows.append(Row(method, paper_rrms, paper_seconds, float(result.attrs["rrms"]),
                        float(result.attrs["rms_m"]), time.perf_counter() - start))
    return rows
