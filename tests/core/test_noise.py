"""The noise floor of the distance, and how the refinement uses it, on a toy stochastic model."""

import json

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer.evaluation import Pipeline, measure_noise_floor, noise_seeds
from physinfer.loop import run_refinement, select_best
from physinfer.parameters import ParameterSpace, ParameterSpec
from physinfer.refinement import SearchSpec
from physinfer.roles import Embedder, Renderer, Simulator, Target
from physinfer.rundir import SELECTION_FILE, RunDirectory, TrialRecord
from physinfer.types import Clip, Trajectory

SPACE = ParameterSpace([ParameterSpec("a", (0.0, 2.0))])


class NoisySimulator(Simulator):
    """One vertex at height ``a`` plus seed noise of standard deviation ``sigma``."""

    parameter_space = SPACE

    def __init__(self, sigma: float) -> None:
        self.sigma = sigma

    def simulate(self, params, *, seed=0):
        rng = np.random.default_rng(seed)
        z = params["a"] + self.sigma * rng.standard_normal()
        vertices = np.full((4, 3, 3), z, dtype=np.float32)
        return Trajectory(vertices=vertices, faces=np.array([[0, 1, 2]], dtype=np.int32), fps=25.0)


class PassRenderer(Renderer):
    default_render_params: dict = {}

    def render(self, trajectory, render_params=None):
        level = np.clip(trajectory.vertices[:, :1, :1, None] * 100, 0, 255).astype(np.uint8)
        return Clip(frames=np.broadcast_to(level, (4, 2, 2, 1)).copy(), fps=trajectory.fps)


class MeanEmbedder(Embedder):
    fps, n_frames = 25.0, 4

    def embed(self, clip):
        return np.array([clip.frames.mean() / 100.0])


def pipeline(sigma):
    return Pipeline(phenomenon=None, simulator=NoisySimulator(sigma), renderer=PassRenderer(), embedder=MeanEmbedder())


def test_noise_seeds_are_distinct_deterministic_and_avoid_the_run_seed():
    seeds = noise_seeds(7, 6)
    assert len(set(seeds)) == 6 and 7 not in seeds
    assert seeds == noise_seeds(7, 6) and seeds != noise_seeds(8, 6)


def test_floor_grows_with_the_seed_noise_and_gap_with_the_offset():
    quiet = measure_noise_floor(pipeline(0.01), {"a": 1.0}, {}, seeds=noise_seeds(0, 6))
    loud = measure_noise_floor(pipeline(0.2), {"a": 1.0}, {}, seeds=noise_seeds(0, 6))
    assert len(loud.pairwise) == 15 and loud.to_target is None
    assert loud.floor > 20 * quiet.floor
    near = measure_noise_floor(pipeline(0.05), {"a": 1.0}, {}, seeds=noise_seeds(0, 6), target_embedding=np.array([1.0]))
    far = measure_noise_floor(pipeline(0.05), {"a": 1.5}, {}, seeds=noise_seeds(0, 6), target_embedding=np.array([1.0]))
    assert far.gap > 10 * near.gap
    summary = far.summary()
    assert summary["ratio"] > 10 and json.dumps(summary)


def test_the_floor_is_simulated_as_one_batch_and_counts_failed_seeds():
    class Batched(NoisySimulator):
        calls: list = []

        def simulate_batch(self, params, *, seeds):
            self.calls.append(list(seeds))
            if 13 in seeds:
                raise RuntimeError("one member blew up")
            return super().simulate_batch(params, seeds=seeds)

        def simulate(self, params, *, seed=0):
            if seed == 13:
                raise RuntimeError("blew up")
            return super().simulate(params, seed=seed)

    batched = Pipeline(phenomenon=None, simulator=Batched(0.1), renderer=PassRenderer(), embedder=MeanEmbedder())
    seeds = noise_seeds(0, 5)
    floor = measure_noise_floor(batched, {"a": 1.0}, {}, seeds=seeds)
    assert Batched.calls == [seeds], "one batch call for all seeds"
    assert floor.pairwise == measure_noise_floor(pipeline(0.1), {"a": 1.0}, {}, seeds=seeds).pairwise
    failing = measure_noise_floor(batched, {"a": 1.0}, {}, seeds=[11, 12, 13])
    assert failing.n_failed == 1 and failing.seeds == [11, 12], "the failing seed alone is dropped"

def test_noise_floor_needs_two_seeds():
    with pytest.raises(ValueError, match="two seeds"):
        measure_noise_floor(pipeline(0.1), {"a": 1.0}, {}, seeds=[1])


def loop_config(**settings):
    """A search that measures no noise unless asked (the command's defaults measure both)."""
    return SearchSpec(**{"noise_samples": 0, "floor_samples": 0, **settings})


def run(tmp_path, config):
    target = Target(clip=PassRenderer().render(NoisySimulator(0.0).simulate({"a": 1.3})), truth={"a": 1.3}, render_params={})
    from physinfer.optimizers.random import RandomOptimizer

    return run_refinement(
        pipeline(0.05), target, RandomOptimizer, RunDirectory(tmp_path / "run"), config,
        run_info={"plugin": "toy", "seeds_per_trial": config.seeds_per_trial},
    )


def test_refinement_measures_the_observation_noise_and_reports_the_floor(tmp_path):
    result = run(tmp_path, loop_config(steps=6, optimizer="random", noise_samples=4, floor_samples=4))
    prior = json.loads((tmp_path / "run" / "noise_prior.json").read_text())
    assert prior["sem"] > 0 and result.extra["observation_sem"] == prior["sem"]
    floor = result.extra["noise_floor"]
    assert floor["n"] == 4 and floor["floor"] > 0 and floor["gap"] > 0


def test_noise_seeds_of_none_is_empty():
    # n = 0 once returned four seeds, so every trial of a refinement was simulated five times.
    assert noise_seeds(0, 0) == [] and noise_seeds(3, -1) == []
    assert loop_config(seed=5).trial_seeds() == [5]


@pytest.mark.parametrize("seeds_per_trial", [1, 3])
def test_seeds_per_trial_costs_that_many_simulations_per_trial(tmp_path, monkeypatch, seeds_per_trial):
    seeds_seen = []
    original = NoisySimulator.simulate

    def counting(self, params, *, seed=0):
        if self.sigma > 0:  # not the noiseless simulator that makes the target
            seeds_seen.append(seed)
        return original(self, params, seed=seed)

    monkeypatch.setattr(NoisySimulator, "simulate", counting)
    result = run(tmp_path, loop_config(steps=3, optimizer="random", seeds_per_trial=seeds_per_trial))
    assert "noise_floor" not in result.extra and result.extra["observation_sem"] is None
    assert len(seeds_seen) == 3 * seeds_per_trial
    assert seeds_seen[:seeds_per_trial] == loop_config(seeds_per_trial=seeds_per_trial).trial_seeds()
    assert loop_config(seeds_per_trial=3, seed=5).trial_seeds()[0] == 5


@pytest.mark.parametrize(
    "field, value",
    [("seeds_per_trial", 0), ("noise_samples", 1), ("floor_samples", -1), ("select_top", 1), ("select_seeds", 0)],
)
def test_bad_noise_settings_are_user_errors(field, value):
    with pytest.raises(UserInputError, match=field.replace("_", "-")):
        loop_config(**{field: value}).validate()


def _record(step, a, distance):
    x = [a - 1.0]  # SPACE is [0, 2]: x = a - 1
    return TrialRecord(step=step, index=step, x=x, params={"a": a}, distance=distance)


def test_selection_re_simulates_the_finalists_and_undoes_a_lucky_seed(tmp_path, monkeypatch):
    target = Target(clip=PassRenderer().render(NoisySimulator(0.0).simulate({"a": 1.3})), render_params={})
    # Step 1 logged the lowest distance, but only by luck: its θ is 0.5 away from the truth.
    records = [_record(0, 1.0, 0.2), _record(1, 1.8, 0.001), _record(2, 1.3, 0.01), _record(3, 1.3, 0.02)]
    run_dir = RunDirectory(tmp_path / "run")
    run_dir.path.mkdir(parents=True)
    seeds_seen = []
    original = NoisySimulator.simulate

    def counting(self, params, *, seed=0):
        seeds_seen.append(seed)
        return original(self, params, seed=seed)

    monkeypatch.setattr(NoisySimulator, "simulate", counting)
    config = loop_config(seed=4, select_top=3, select_seeds=2)
    target_embedding = MeanEmbedder().embed(target.clip)
    selection = select_best(records, pipeline(0.01), target, target_embedding, run_dir, config)
    # Finalists: the three best *distinct* θ (step 3 repeats step 2's θ); fresh seeds only.
    assert [f["step"] for f in selection["finalists"]] == [1, 2, 0]
    assert selection["chosen_step"] == 2
    assert len(seeds_seen) == 6 and set(seeds_seen) == set(selection["seeds"])
    assert config.seed not in seeds_seen and not set(seeds_seen) & set(noise_seeds(config.seed, 8))
    assert (run_dir.path / SELECTION_FILE).is_file()
    # The same finalists again: read back, nothing re-simulated.
    again = select_best(records, pipeline(0.01), target, target_embedding, run_dir, config)
    assert again["chosen_step"] == 2 and len(seeds_seen) == 6
    # Fewer than two distinct successful trials: nothing to choose between.
    assert select_best(records[2:], pipeline(0.01), target, target_embedding, run_dir, config) is None


def test_refinement_with_selection_reports_the_chosen_trial(tmp_path):
    result = run(tmp_path, loop_config(steps=6, optimizer="random", select_top=3, select_seeds=2))
    selection = result.extra["selection"]
    assert len(selection["finalists"]) == 3 and selection["selection_s"] >= 0
    assert all(len(f["resimulated"]) == 2 for f in selection["finalists"])
    chosen = min(selection["finalists"], key=lambda f: f["score"])
    assert result.best_step == selection["chosen_step"] == chosen["step"]
    assert result.best_distance == chosen["distance"]
    assert "key" not in selection and json.dumps(result.summary()["selection"])
