"""Per-sample randomness: seeds, the train/validation split, and the surface of each sample.

Sample i of a spec with seed s draws everything from one 64-bit seed,
``SeedSequence(s, spawn_key=(i,)).generate_state(1, uint64)``, which the store records:
``numpy.random.SeedSequence(seed).spawn(2 + n_models)`` gives one child for the sample's own
choices (its frequency), one per error model, so a model's draws never depend on the
others, and a last one for the measurement effects (two children of its own: the effect
values, and their realisation: noise, missing points). A child does not depend on how many
are spawned, so a spec without effects draws what it drew before they existed. Any sample
regenerates alone from the spec and its index (or its recorded seed), whatever the order,
worker or number of workers that made the others.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from raysim.dataset import effects
from raysim.dataset.spec import DatasetSpec
from raysim.surface.deformation import Deformation, NoDeformation, Sum

# spawn key of the split's generator: sample indices stay below 10**7, so it never meets one
SPLIT_KEY = 0x53504C54


@dataclass(frozen=True)
class SampleDraw:
    """One sample's random surface: ``deformation`` (m, the scene's own plus the drawn errors),
    ``frequency_index`` into the spec's frequencies, and the flat ``params`` the store keeps
    (``<model>_present``, ``<model>_rms`` in m, ``<model>_<parameter>``)."""

    index: int
    seed: int
    frequency_index: int
    deformation: Deformation
    params: dict[str, Any]
    effects: dict[str, Any] | None = None  # the measurement effects' values (effects.VARIABLES)
    realisation: np.random.SeedSequence | None = None  # seeds the effects' noise and losses

    def measured(self, clean, ideal, spec: DatasetSpec) -> np.ndarray | None:
        """The measured intensity of this sample from its clean and ideal ones (no effects:
        None)."""
        if self.effects is None:
            return None
        scene = spec.scene
        return effects.apply(clean, ideal, scene.sphere, scene.F, scene.D, self.effects,
                             np.random.default_rng(self.realisation))


def sample_seed(spec_seed: int, index: int) -> int:
    """The 64-bit seed of sample ``index`` (see the module docstring)."""
    state = np.random.SeedSequence(spec_seed, spawn_key=(index,)).generate_state(1, np.uint64)
    return int(state[0])


def validation_mask(spec: DatasetSpec) -> NDArray[np.bool_]:
    """True for the samples of the validation split: round(fraction * samples) of them,
    chosen by a permutation seeded from the spec's seed (samples are i.i.d., so any fixed
    choice is a random split; the permutation only spreads it over the index range)."""
    rng = np.random.default_rng(np.random.SeedSequence(spec.seed, spawn_key=(SPLIT_KEY,)))
    mask = np.zeros(spec.samples, dtype=bool)
    mask[rng.permutation(spec.samples)[: spec.n_validation]] = True
    return mask


def draw_sample(spec: DatasetSpec, index: int, seed: int | None = None) -> SampleDraw:
    """The random surface of sample ``index`` (0-based); ``seed`` overrides the derived one."""
    if not 0 <= index < spec.samples:
        raise IndexError(f"sample {index} is outside 0..{spec.samples - 1}")
    seed = sample_seed(spec.seed, index) if seed is None else int(seed)
    children = np.random.SeedSequence(seed).spawn(2 + len(spec.models))
    own = np.random.default_rng(children[0])
    f_index = int(own.integers(len(spec.frequencies))) if len(spec.frequencies) > 1 else 0
    grid = spec.grid
    parts: list[Deformation] = [] if isinstance(spec.scene.deformation, NoDeformation) \
        else [spec.scene.deformation]
    params: dict[str, Any] = {}
    for model, child in zip(spec.models, children[1:-1], strict=True):
        deformation, values = model.draw(np.random.default_rng(child), grid)
        if deformation is not None:
            parts.append(deformation)
        params.update({f"{model.name}_{key}": value for key, value in values.items()})
    total: Deformation = NoDeformation() if not parts else parts[0] if len(parts) == 1 else Sum(tuple(parts))
    values = realisation = None
    if spec.measurement is not None:
        draw_seq, realisation = children[-1].spawn(2)
        values = spec.measurement.draw(np.random.default_rng(draw_seq))
        params.update({f"{effects.PREFIX}{key}": value for key, value in values.items()})
    return SampleDraw(index, seed, f_index, total, params, values, realisation)
