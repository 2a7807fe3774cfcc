"""The plan of a dataset: every simulation's split, θ and seed, grouped into work units.

Randomness is keyed, never sequential: the seeds of simulation ``local`` of split ``s``
come from ``SeedSequence(seed, spawn_key=(s, local, stream, ...))`` with stream 0 for θ,
1 for the simulator's seed, ``(2, r)`` for ζ of render ``r`` and 3 for the ranged scene
settings (``--scene-range``; keyed like θ, so simulations sharing θ share the scene). With the preset's
``seeds_per_theta`` = n > 1, θ of simulation ``local`` comes from the θ stream of
``local // n`` instead, so n consecutive simulations share θ while each keeps its own
simulator seed (n = 1 is the plain rule). So a dataset does not
depend on how many workers made it or in which order units finished, and growing one
split leaves the simulations of the others unchanged. Units are consecutive runs of at
most ``sims_per_unit`` simulations of one split; their composition is fixed by the
preset, because a batched simulator may give different bits for different batches.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from physinfer.datasets.generator import DatasetGenerator
from physinfer.datasets.presets import SPLITS, DatasetPreset

THETA_STREAM, SIM_STREAM, RENDER_STREAM, SCENE_STREAM = 0, 1, 2, 3


def seed_sequence(seed: int, split: str, local: int, *stream: int) -> np.random.SeedSequence:
    """The seed sequence of one random stream of simulation ``local`` of ``split``.

    Args:
        seed: The dataset seed.
        split: ``"train"``, ``"val"`` or ``"test"``.
        local: Index of the simulation within its split.
        *stream: ``THETA_STREAM``, ``SIM_STREAM`` or ``RENDER_STREAM, r``.
    """
    return np.random.SeedSequence(seed, spawn_key=(SPLITS.index(split), local, *stream))


def render_rng(seed: int, split: str, local: int, render: int) -> np.random.Generator:
    """The generator ζ of render ``render`` of a simulation is drawn from."""
    return np.random.default_rng(seed_sequence(seed, split, local, RENDER_STREAM, render))


@dataclass(frozen=True)
class SimulationPlan:
    """One simulation of the dataset.

    Attributes:
        sim: Global simulation id (train first, then val, then test).
        split: Its split.
        local: Its index within the split.
        params: θ, physical values by name.
        seed: The simulator's seed (31 bits, accepted by every RNG).
        n_renders: How many clips are rendered from it.
        first_render: Global id of its first render; its renders are consecutive.
        scene: Its ranged scene settings (``--scene-range``), or ``None`` (the dataset's one scene).
    """

    sim: int
    split: str
    local: int
    params: dict[str, float]
    seed: int
    n_renders: int
    first_render: int
    scene: dict[str, float] | None = None


@dataclass(frozen=True)
class UnitPlan:
    """One work unit: a batch of simulations of one split and all their renders.

    Attributes:
        unit: Unit id (its shard is ``shards/unit-<id>.npy``).
        split: The split of all its simulations.
        sims: The simulations, in id order.
    """

    unit: int
    split: str
    sims: tuple[SimulationPlan, ...]

    @property
    def n_renders(self) -> int:
        """Clips this unit renders when no simulation fails."""
        return sum(s.n_renders for s in self.sims)


def plan_dataset(generator: DatasetGenerator, preset: DatasetPreset, seed: int) -> list[UnitPlan]:
    """Sample θ and seeds of every simulation and group them into units.

    Simulation ``local`` of a split takes θ from the key of
    ``local // preset.seeds_per_theta`` and its simulator seed from its own key.

    Raises:
        ValueError: when the generator samples θ outside its parameter space.
    """
    units: list[UnitPlan] = []
    sim_id = render_id = 0
    for split in SPLITS:
        sims: list[SimulationPlan] = []
        for local in range(preset.sims[split]):
            theta_key = local // preset.seeds_per_theta
            params = generator.sample_params(
                np.random.default_rng(seed_sequence(seed, split, theta_key, THETA_STREAM))
            )
            _check_within_bounds(generator, params)
            sim_seed = int(seed_sequence(seed, split, local, SIM_STREAM).generate_state(1)[0] & 0x7FFFFFFF)
            n_renders = preset.renders_of(split, local)
            scene = generator.sample_scene(
                np.random.default_rng(seed_sequence(seed, split, theta_key, SCENE_STREAM))
            )
            sims.append(SimulationPlan(sim_id, split, local, params, sim_seed, n_renders, render_id, scene))
            sim_id += 1
            render_id += n_renders
        for start in range(0, len(sims), preset.sims_per_unit):
            units.append(UnitPlan(len(units), split, tuple(sims[start : start + preset.sims_per_unit])))
    return units


def _check_within_bounds(generator: DatasetGenerator, params: dict[str, float]) -> None:
    space = generator.parameter_space
    if set(params) != set(space.names):
        raise ValueError(
            f"{type(generator).__name__}.sample_params returned {sorted(params)}, "
            f"expected the parameters {space.names}"
        )
    for spec in space:
        low, high = spec.bounds
        if not low <= params[spec.name] <= high:
            raise ValueError(
                f"{type(generator).__name__}.sample_params drew {spec.name}={params[spec.name]} "
                f"outside [{low}, {high}]"
            )
