"""From journal records to a measured FieldMap (docs/physics.md data contract, method ``measured``).

Per cell: intensity = mean power / ``power_unit`` / g(n) * (r / R)^2 (the last factor only
with ``refer_to_sphere``). g(n) is the receiver gain at step n relative to the first
reference reading (see :mod:`hardware.drift`: as read, smoothed, or 1), interpolated
linearly in the step index between the references (held beyond the first and last); r is the
probe's distance from the focus from the read-back axes and the rig file's calibration.
``intensity_std`` is the standard error of the mean (sample standard deviation of the
readings over sqrt(count), NaN with a single reading). ``intensity_ideal`` is the ideal
paraboloid's GO value (rho / R)^2 at the commanded cell centres (0 beyond the rim image), as
the rig's probe reads it (:func:`raysim.maps.probe.ideal_weight`: times its reading of the
ideal reflected polarisation; 1 for the ideal |E|^2 meter), so that FA compares like with like;
a polarised probe's scan records the plan's incident ``polarization`` (rad) as well.
Cells without a record stay NaN, so a FieldMap can be written from a partial journal.

A plan with obstacles (:attr:`hardware.plan.ScanPlan.blocked_share`) gives the FieldMap what a
simulated one carries (:func:`raysim.optics.blockage.fieldmap_variables`): ``blocked``,
``blocked_share`` and the obstacles' triangles, and an ``intensity_ideal`` that is the blocked
ideal, the exact ideal above times (1 - blocked share). Blocked cells keep their readings (the
meter read whatever field is there); the inversion treats them as missing samples.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from hardware.drift import chi2_limit, drift, reading_noise
from hardware.journal import Record
from hardware.plan import REFERENCE, SAMPLE, ScanPlan
from hardware.rig import rig_attrs
from raysim.maps.fieldmap import fieldmap
from raysim.maps.probe import ideal_weight
from raysim.maps.sphere import ideal_go_intensity
from raysim.optics.blockage import fieldmap_variables

CELL_VARS = {
    "power": ("W", "mean power-meter reading"),
    "drift_db": ("dB", "receiver gain drift removed, from the reference readings"),
    "slider_command": ("rad", "commanded slider axis position"),
    "rotation_command": ("rad", "commanded rotation axis position"),
    "slider_readback": ("rad", "read-back slider axis position"),
    "rotation_readback": ("rad", "read-back rotation axis position"),
    "theta_probe": ("rad", "probe polar angle from the read-back axes and the rig calibration"),
    "phi_probe": ("rad", "probe azimuth from the read-back axes and the rig calibration"),
    "r_probe": ("m", "probe distance from the focus from the read-back axes and calibration"),
    "time": ("s since 1970-01-01T00:00:00Z", "time of the first reading"),
    "sample_index": ("1", "step index in the scan (references included)"),
}


def build_fieldmap(plan: ScanPlan, records: Sequence[Record],
                   attrs: Mapping[str, Any] | None = None) -> xr.Dataset:
    """The measured FieldMap of ``plan`` from its journal ``records`` (see the module doc)."""
    grid = plan.grid
    shape = (grid.n_theta, grid.n_phi)
    cells = {name: np.full(shape, np.nan) for name in CELL_VARS}
    cells["sample_index"] = np.full(shape, -1, dtype=np.int64)
    intensity = np.full(shape, np.nan)
    std = np.full(shape, np.nan)
    refs = [r for r in records if r.kind == REFERENCE]
    noise = reading_noise([r for r in records if r.kind == SAMPLE], refs) \
        if any(len(r.power) == 1 for r in refs) else None
    gain = drift(refs, plan.drift_correction, plan.drift_window, noise)
    R = plan.rig.radius
    for rec in records:
        if rec.kind != SAMPLE:
            continue
        i, j = rec.i, rec.j
        readings = np.asarray(rec.power, dtype=np.float64)
        g = gain.at(rec.n)
        theta_p, phi_p, r_p = plan.rig.probe(*rec.readback)
        scale = (r_p / R) ** 2 if plan.refer_to_sphere else 1.0
        factor = scale / (plan.power_unit * g)
        intensity[i, j] = readings.mean() * factor
        if readings.size > 1:
            std[i, j] = readings.std(ddof=1) / np.sqrt(readings.size) * factor
        values = {"power": readings.mean(), "drift_db": 10.0 * np.log10(g),
                  "slider_command": rec.command[0], "rotation_command": rec.command[1],
                  "slider_readback": rec.readback[0], "rotation_readback": rec.readback[1],
                  "theta_probe": theta_p, "phi_probe": phi_p, "r_probe": r_p,
                  "time": rec.time, "sample_index": rec.n}
        for name, value in values.items():
            cells[name][i, j] = value
    ideal = ideal_intensity(plan)
    # recorded where it matters (a polarised probe, a wave model): older scans had neither
    probe_attrs = {"polarization": plan.polarization} \
        if plan.polarization != 0.0 or not plan.rig.probe_response.ideal else {}
    extra: dict[str, tuple[tuple[str, ...], np.ndarray, dict[str, str]]] = {
        name: (("theta", "phi"), cells[name], {"units": unit, "long_name": text})
        for name, (unit, text) in CELL_VARS.items()
    }
    ref_vars = {
        "reference_index": (gain.index.astype(np.int64), "1",
                            "step index of the reference reading"),
        "reference_power": (gain.power, "W", "mean reading at the reference position"),
        "reference_gain_db": (10.0 * np.log10(gain.gains), "dB",
                              "receiver gain applied at the reference, relative to the first"),
        "reference_time": (np.array([r.time for r in refs]), "s since 1970-01-01T00:00:00Z",
                           "time of the reference reading"),
    }
    for name, (values, unit, text) in ref_vars.items():
        extra[name] = (("reference",), values, {"units": unit, "long_name": text})
    blockage_attrs: dict[str, Any] = {}
    if plan.blocked_share is not None and plan.obstacle_mesh is not None:
        blockage_vars, blockage_attrs = fieldmap_variables(plan.blocked_share, plan.obstacle_mesh)
        extra.update(blockage_vars)
    all_attrs: dict[str, Any] = {
        **rig_attrs(plan.rig),
        "power_unit": plan.power_unit,
        "samples_per_point": plan.samples_per_point,
        "settle_s": plan.settle_s,
        "reference_every_lines": plan.reference_every,
        "reference_samples": plan.reference_samples,
        "drift_correction": plan.drift_correction,
        "drift_correction_applied": gain.applied,
        "drift_window_applied": gain.window,
        "drift_chi2": gain.chi2,
        "drift_chi2_limit": chi2_limit(gain.index.size),
        # the smoothing's own check (hardware.drift): why it narrowed the window or followed
        # the references, so that a rehearsal's analyst sees it ("" when it did as asked)
        "drift_fit_chi2": gain.fit_chi2,
        "drift_note": gain.note,
        "drift_window": plan.drift_window,
        "reference_theta": plan.reference[0],
        "reference_phi": plan.reference[1],
        "refer_to_sphere": int(plan.refer_to_sphere),
        "samples_expected": grid.n_theta * grid.n_phi,
        "samples_measured": int(np.count_nonzero(cells["sample_index"] >= 0)),
        "plan": plan.text,
        "rig": plan.rig_text,
        **probe_attrs,
        **blockage_attrs,
        **(attrs or {}),
    }
    return fieldmap(grid, intensity, ideal, focal_length=plan.focal_length,
                    diameter=plan.diameter, frequency_hz=plan.frequency_hz, method="measured",
                    sampling="centre", intensity_std=std, attrs=all_attrs, extra=extra)


def ideal_intensity(plan: ScanPlan) -> np.ndarray:
    """(n_theta, n_phi): the ideal paraboloid's GO intensity at the plan's cell centres as the
    rig's probe reads it (relative to the incident wave), blocked by the plan's obstacles:
    times (1 - blocked share) in every cell, as a GO scene's ideal cell means are."""
    grid = plan.grid
    ideal = np.repeat(ideal_go_intensity(grid.theta, plan.focal_length, plan.rig.radius,
                                         plan.diameter)[:, None], grid.n_phi, axis=1)
    if not plan.rig.probe_response.ideal:
        ideal = ideal * ideal_weight(plan.rig.probe_response, grid.theta[:, None], grid.phi[None, :],
                                     plan.focal_length, plan.polarization)
    if plan.blocked_share is not None:
        ideal = ideal * (1.0 - np.clip(plan.blocked_share, 0.0, 1.0))
    return ideal
