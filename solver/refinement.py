"""The refinement's set-up: which forward model, which preconditioner, what to record.

Frame and units as :mod:`solver.nonlinear`. The model is the caller's (``forward``), the one
named (``model``: go, po, po+ptd), or by default the one that made the data (the FieldMap's
``method``; GO for a measured scan). GO data and the GO model keep the GO inversion as the
preconditioner and the power-balance scale; a wave model (PO, PO+PTD) gets
:class:`solver.wave.WaveCorrection`, built from the model's ideal complex field (computed
here, once per scan geometry, then cached by the model), and fits the scan's scale with the
surface when the gain is not trusted.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from raysim.progress import Progress, monotone
from solver.forward import (
    WAVE_MODELS,
    Forward,
    ForwardModel,
    WaveModel,
    as_model,
    forward_for,
    model_for_method,
)
from solver.linear import LinearInverse
from solver.nonlinear import Correct


@dataclass
class RefinementSetup:
    """What :func:`solver.nonlinear.refine` needs, and the words for the SurfaceMap."""

    forward: ForwardModel | None
    correct: Correct
    fit_gain: bool
    progress: Progress | None
    model: str            # go, po, po+ptd, the caller's name for its model, or none
    choice: str           # how the model was chosen
    description: str      # the model in words
    preconditioner: str   # the preconditioner in words

    @property
    def wave(self) -> bool:
        return self.model in WAVE_MODELS


@dataclass(frozen=True)
class ModelChoice:
    """The refinement's forward model before anything is computed with it."""

    forward: ForwardModel | None
    name: str           # go, po, po+ptd, the caller's name for its model, or none
    choice: str         # how it was chosen
    description: str    # the model in words

    @property
    def wave(self) -> bool:
        return self.name in WAVE_MODELS


def choose_model(attrs: dict, iterations: int, model: str | None,
                 forward: ForwardModel | Forward | None, device: str | None,
                 obstacles: Any = None, radiator: str = "fast", radiator_tol: float = 1e-6) -> ModelChoice:
    """The caller's ``forward``, else the ``model`` named, else the data's (FieldMap attrs).

    A caller's model says what physics it is through its ``name`` (go, po, po+ptd; a plain
    function is wrapped as ``caller``, :func:`solver.forward.as_model`). A model made here
    puts the scan's ``obstacles`` (an ObstacleMesh, or None) in its beam and sums a wave
    model's elements with ``radiator`` (``fast`` or ``direct``, to ``radiator_tol``).
    """
    data_method = str(attrs.get("method", ""))
    if forward is not None:
        chosen = as_model(forward)
        return ModelChoice(chosen, chosen.name, "given by the caller", f"caller's ({chosen.name})")
    if iterations == 0:
        return ModelChoice(None, "none", "refine 0", "none (no refinement)")
    name = model or model_for_method(data_method)
    forward, description = forward_for(name, attrs, device, obstacles=obstacles, radiator=radiator,
                                       radiator_tol=radiator_tol)
    return ModelChoice(forward, name, "requested" if model else
                       f"from the data's method {data_method!r}", description)


def refinement_setup(inverse: LinearInverse, chosen: ModelChoice, iterations: int, fit_gain: bool,
                     progress: Progress | None = None) -> RefinementSetup:
    """The preconditioner for ``chosen`` on a scan; ``inverse`` is its linear inversion.

    ``fit_gain``: the scan's scale is not trusted (gain mode ``power``); a wave model then
    fits it with the surface. A wave model's ideal field is computed here (``progress``).
    """
    scan = inverse.scan
    progress = monotone(progress) if progress is not None else None
    forward, name = chosen.forward, chosen.name
    if iterations == 0 or not chosen.wave or not isinstance(forward, WaveModel):
        text = "GO inversion (resample, divide by G, Poisson solve)" if iterations else "none"
        return RefinementSetup(forward, inverse.correct, False, progress, name, chosen.choice,
                               chosen.description, text)
    from solver.wave import WaveCorrection

    report = progress or (lambda stage, fraction: None)
    # the first of the refinement's iterations + 2 planned model runs (solver.nonlinear.refine)
    E0 = forward.ideal_field(scan.sphere, scan.F, scan.D,
                             lambda stage, f: report(f"ideal reflector: {stage}",
                                                     f / (iterations + 2)))
    weight = inverse.weight if inverse.weight is not None else np.ones_like(scan.intensity_ideal)
    fresnel = bool(getattr(forward, "fresnel_smoothing", True))
    correct = WaveCorrection(inverse, E0, float(scan.attrs["frequency_hz"]),
                             float(scan.attrs.get("polarization", 0.0)), weight, fit_gain, fresnel)
    rest = "the GO inversion"
    if correct.filter is not None:
        axis, rim = correct.filter.shortest_period()
        rest += (f" after a Fresnel filter (periods down to {axis:.1f} m on the axis, {rim:.1f} m "
                 f"at the rim)")
    text = (f"two-level wave preconditioner: the focus-like shape B"
            f"{' and the scan scale' if fit_gain else ''} by least squares with the model's "
            f"edge-wave response, the rest by {rest}")
    return RefinementSetup(forward, correct, fit_gain, progress, name, chosen.choice,
                           chosen.description, text)

