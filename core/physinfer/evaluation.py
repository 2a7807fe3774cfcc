"""One model's pipeline: built from the registry, evaluated against a target, and its noise.

A :class:`Pipeline` holds a phenomenon's simulator (with its effects and ``--fix``), renderer
and embedder. :func:`build_pipeline` makes it from the registry; :func:`evaluate_batch` and its
helpers simulate θ, render it with ζ, embed the clip and measure the squared distance to the
target; :func:`measure_noise_floor` re-simulates one θ under other seeds, since a distance is
only meaningful against the spread between two realisations of the same θ (a flag in the
wind is chaotic and stochastic). The loop (:mod:`physinfer.loop`), the trial workers, the
posterior and the diagnosis all build and evaluate models here. A simulation that raises,
returns NaN or blows up is a failed trial (an error string), never an exception: it is a
property of θ, not a bug. The video a pipeline is compared with is loaded by
:mod:`physinfer.target`.
"""

from __future__ import annotations

import fnmatch
import itertools
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from physinfer.devices import check_device
from physinfer.errors import PhysinferError, SimulationFailed, UserInputError
from physinfer.fixed import FixedParameters, resolve_fixed, split_fixed
from physinfer.parameters import (
    ParameterSpace,
    UnknownParameterError,
    refuse_repeats,
)
from physinfer.registry import Registry, accepts_keyword
from physinfer.roles import Effect, Embedder, Phenomenon, Renderer, Simulator, Target
from physinfer.scene import bind_scene, resolve_scene
from physinfer.types import Clip, Trajectory


class ClipWorkers(Protocol):
    """Simulates and renders a step's jobs elsewhere (:class:`~physinfer.trial_workers.TrialWorkers`)."""

    def clips(
        self,
        params: Sequence[Mapping[str, float]],
        seeds: Sequence[int],
        render_params: Mapping[str, Any],
    ) -> list[tuple[Clip | None, str | None, dict[str, float]]]:
        """Job ``j`` = ``(params[j], seeds[j])`` as :func:`make_clips` makes it here; in order."""
        ...


@dataclass
class Pipeline:
    """The built roles of one phenomenon for one run.

    ``workers``, when set, simulates and renders the trials of each step on an executor
    (:class:`ClipWorkers`, attached by :func:`physinfer.trial_workers.trial_workers`)
    instead of in this process.
    """

    phenomenon: Phenomenon
    simulator: Simulator
    renderer: Renderer
    embedder: Embedder
    effects: Sequence[Effect] = ()
    workers: ClipWorkers | None = None


def squared_distance(a: np.ndarray, b: np.ndarray) -> float:
    """``||a - b||²``, the paper's distance."""
    return float(np.sum((np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)) ** 2))


NON_FINITE = "the simulation produced NaN or infinite positions"
NON_FINITE_DISTANCE = "the embedding distance is not finite"


def simulate_one(simulator: Simulator, params: Mapping[str, float], seed: int) -> tuple[Trajectory | None, str | None]:
    """One simulation as ``(trajectory, None)``, or ``(None, reason)`` when it fails.

    Any exception of the simulator is a property of this θ (a blow-up, an unstable
    setting), not a bug of the loop, so it becomes a failed trial.
    """
    try:
        trajectory = simulator.simulate(params, seed=seed)
    except Exception as exc:
        return None, f"{type(exc).__name__}: {exc}"
    if not trajectory.is_finite():
        return None, NON_FINITE
    return trajectory, None


def simulate_many(
    simulator: Simulator, params: Sequence[Mapping[str, float]], seeds: Sequence[int]
) -> list[tuple[Trajectory | None, str | None]]:
    """:func:`simulate_one` for ``B`` jobs, through the simulator's batched engine.

    A batch call fails as a whole when one member fails; only then are the jobs simulated
    one by one, to learn which failed and why (failures are rare, so the batch's speed is
    kept in the common case).
    """
    try:
        trajectories = simulator.simulate_batch(params, seeds=seeds)
    except Exception:
        return [simulate_one(simulator, p, s) for p, s in zip(params, seeds, strict=True)]
    return [(t, None) if t.is_finite() else (None, NON_FINITE) for t in trajectories]


#: Simulates, renders and embeds clips elsewhere (a diagnosis's idle workers): ``(θ list,
#: seeds)`` → one embedding per pair, ``None`` for a failed simulation, each what
#: :func:`simulate_and_embed` gives here (the same simulator, ζ and embedder).
ClipEmbedder = Callable[[Sequence[Mapping[str, float]], Sequence[int]], "list[np.ndarray | None]"]


def simulate_and_embed(
    pipeline: Pipeline,
    params: Mapping[str, float],
    render_params: Mapping[str, Any],
    seed: int,
) -> tuple[np.ndarray | None, str | None, dict[str, float]]:
    """Simulate, render and embed one θ; returns ``(embedding, error, timings)``.

    A failing simulation gives ``(None, reason, timings)``; render and embed errors
    propagate (they are not properties of θ).
    """
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    trajectory, error = simulate_one(pipeline.simulator, params, seed)
    if trajectory is None:
        timings["simulate"] = time.perf_counter() - t0
        return None, error, timings
    t1 = time.perf_counter()
    clip = pipeline.renderer.render(trajectory, render_params)
    t2 = time.perf_counter()
    embedding = np.asarray(pipeline.embedder.embed(clip))
    timings.update(simulate=t1 - t0, render=t2 - t1, embed=time.perf_counter() - t2)
    return embedding, None, timings


def evaluate(
    pipeline: Pipeline,
    params: Mapping[str, float],
    target_embedding: np.ndarray,
    render_params: Mapping[str, Any],
    seed: int,
) -> tuple[float | None, str | None, dict[str, float]]:
    """:func:`simulate_and_embed` and the distance to the target: ``(distance, error, timings)``."""
    embedding, error, timings = simulate_and_embed(pipeline, params, render_params, seed)
    if embedding is None:
        return None, error, timings
    distance = squared_distance(embedding, target_embedding)
    if not np.isfinite(distance):
        return None, NON_FINITE_DISTANCE, timings
    return distance, None, timings


def evaluate_mean(
    pipeline: Pipeline,
    params: Mapping[str, float],
    target_embedding: np.ndarray,
    render_params: Mapping[str, Any],
    seeds: Sequence[int],
) -> tuple[float | None, str | None, dict[str, float]]:
    """:func:`evaluate` under each seed; the mean distance (failed if any seed fails)."""
    distances, totals = [], {}
    for seed in seeds:
        distance, error, timings = evaluate(pipeline, params, target_embedding, render_params, seed)
        for phase, seconds in timings.items():
            totals[phase] = totals.get(phase, 0.0) + seconds
        if distance is None:
            return None, error, totals
        distances.append(distance)
    return float(np.mean(distances)), None, totals


def evaluate_batch(
    pipeline: Pipeline,
    params: Sequence[Mapping[str, float]],
    target_embedding: np.ndarray,
    render_params: Mapping[str, Any],
    seeds: Sequence[int],
) -> list[tuple[float | None, str | None, dict[str, float]]]:
    """:func:`evaluate_mean` of ``q`` θ, simulated as one batch and embedded together.

    Every θ is simulated under every seed and rendered (:func:`make_clips`); the clips are
    embedded with ``embed_many``. A θ's timings are its simulate and render time (its
    share of a batched simulation) plus its share of the embedding time. One θ in this
    process takes the sequential path (:func:`evaluate_mean`), so ``batch_size=1`` runs
    exactly as before.

    Returns:
        One ``(distance, error, timings)`` per θ, in order.
    """
    if len(params) == 1 and pipeline.workers is None:
        return [evaluate_mean(pipeline, params[0], target_embedding, render_params, seeds)]
    jobs = [(i, seed) for i in range(len(params)) for seed in seeds]
    made = make_clips(pipeline, [params[i] for i, _ in jobs], [seed for _, seed in jobs], render_params)
    timings = [{"simulate": 0.0, "render": 0.0, "embed": 0.0} for _ in params]
    errors: list[str | None] = [None] * len(params)
    clips, owners = [], []
    for (i, _), (clip, error, job_timings) in zip(jobs, made, strict=True):
        for phase, seconds in job_timings.items():
            timings[i][phase] += seconds
        if errors[i] is not None:
            continue
        if clip is None:
            errors[i] = error  # failed if any seed fails, as evaluate_mean
            continue
        clips.append(clip)
        owners.append(i)
    t2 = time.perf_counter()
    embeddings = np.asarray(pipeline.embedder.embed_many(clips)) if clips else np.empty((0, 0))
    embed_s = (time.perf_counter() - t2) / max(len(clips), 1)
    distances: list[list[float]] = [[] for _ in params]
    for i, embedding in zip(owners, embeddings, strict=True):
        timings[i]["embed"] += embed_s
        distances[i].append(squared_distance(embedding, target_embedding))
    results = []
    for i in range(len(params)):
        distance = None if errors[i] is not None else float(np.mean(distances[i]))
        if distance is not None and not np.isfinite(distance):
            distance, errors[i] = None, NON_FINITE_DISTANCE
        results.append((distance, errors[i], timings[i]))
    return results


def make_clips(
    pipeline: Pipeline,
    params: Sequence[Mapping[str, float]],
    seeds: Sequence[int],
    render_params: Mapping[str, Any],
) -> list[tuple[Clip | None, str | None, dict[str, float]]]:
    """Simulate and render job ``j`` = ``(params[j], seeds[j])``: ``(clip, error, timings)``.

    On the pipeline's workers when it has them; otherwise all jobs in one
    :func:`simulate_many` call (each job's simulate time is its share of the batch) and
    rendered here one by one. A failed simulation gives ``(None, reason, timings)``.
    """
    if pipeline.workers is not None:
        return pipeline.workers.clips(params, seeds, render_params)
    t0 = time.perf_counter()
    simulated = simulate_many(pipeline.simulator, params, seeds)
    simulate_s = (time.perf_counter() - t0) / max(len(params), 1)
    made: list[tuple[Clip | None, str | None, dict[str, float]]] = []
    for trajectory, error in simulated:
        if trajectory is None:
            made.append((None, error, {"simulate": simulate_s}))
            continue
        t1 = time.perf_counter()
        clip = pipeline.renderer.render(trajectory, render_params)
        made.append((clip, None, {"simulate": simulate_s, "render": time.perf_counter() - t1}))
    return made


# Building a pipeline from the registry.


def build_pipeline(
    registry: Registry,
    plugin: str,
    *,
    effects: Sequence[str] = (),
    embedder: str | None = None,
    weights: Path | None = None,
    device: str | None = None,
    fixed: Sequence[str] = (),
    duration_s: float | None = None,
    embedder_frames: int | None = None,
    scene_set: Mapping[str, Any] | None = None,
) -> Pipeline:
    """Build simulator (with effects), renderer and embedder of a phenomenon.

    Args:
        registry: Loaded plugin registry.
        plugin: Phenomenon name.
        effects: Effect names to switch in.
        embedder: Embedder name, ``None`` for the phenomenon's default; ``""`` for none.
        weights: Embedder weights file (``None``: the shipped default).
        device: torch device for the embedder.
        fixed: ``NAME=VALUE`` items (patterns allowed) held fixed and left out of θ (see
            :mod:`physinfer.fixed`).
        duration_s: Seconds every simulation records (``None``: the phenomenon's default);
            for phenomena whose ``make_simulator`` takes ``duration_s``.
        embedder_frames: Frames the embedder reads (``None``: its default); for embedders
            whose factory takes ``n_frames`` (parameter-free ones; an SDN's are in its weights).
        scene_set: Known scene settings by name (``--scene-set``, strings or values; see
            :mod:`physinfer.scene`); ``None``: the phenomenon's default scene. The pipeline's
            ``phenomenon`` is bound to the validated scene (:func:`physinfer.scene.scene_of`).

    Raises:
        UserInputError: a duration the phenomenon cannot record, frames the embedder
            cannot be told, a device this machine lacks, an effect given twice, or a
            scene setting that is unknown or out of range.
    """
    device = check_device(device)  # refused here, not ignored by an embedder that needs none
    refuse_repeats(effects, "--effect")
    phenomenon = registry.phenomenon(plugin)
    if scene_set:
        phenomenon = bind_scene(phenomenon, resolve_scene(phenomenon, scene_set))
    effect_objs = [registry.effect(name, phenomenon=phenomenon.name) for name in effects]
    simulator = make_simulator(phenomenon, effect_objs, duration_s)
    if fixed:
        with naming_effects(registry, phenomenon.name, effects, "--fix"):
            simulator = FixedParameters(simulator, resolve_fixed(simulator.parameter_space, fixed))
    renderer = phenomenon.make_renderer()
    embedder_obj: Any = None
    if embedder != "":
        name = embedder or phenomenon.default_embedder
        options: dict[str, Any] = {"model": str(weights) if weights else None, "device": device}
        if embedder_frames is not None:
            if not accepts_keyword(registry.get("embedders", name).load(), "n_frames"):
                raise UserInputError(
                    f"--embedder-frames: the embedder {name!r} reads a fixed number of frames (an SDN's "
                    "are set by its weights); use it with a parameter-free embedder such as 'spectral'"
                )
            options["n_frames"] = embedder_frames
        embedder_obj = registry.embedder(name, **options)
    return Pipeline(phenomenon, simulator, renderer, embedder_obj, effect_objs)


class EffectParameterError(UserInputError):
    """A parameter of one of the phenomenon's effects, given while that effect is not switched in.

    Attributes:
        name: The parameter (or pattern) as given.
        option: The option it was given to (``--set``, ``--fix``, ``--truth``).
        effect: The effect it belongs to.
    """

    def __init__(self, name: str, option: str, effect: str) -> None:
        super().__init__(f"{name} (in {option}) belongs to the effect {effect}: add --effect {effect}")
        self.name, self.option, self.effect = name, option, effect

    def __reduce__(self) -> tuple:  # pickled across worker processes
        return (type(self), (self.name, self.option, self.effect))


@contextmanager
def naming_effects(registry: Registry, phenomenon: str, effects: Sequence[str], option: str) -> Iterator[None]:
    """Turn "unknown parameter" into the effect to switch in, when the name is an effect's.

    The effects' parameter spaces are built only when a name is unknown, so a correct
    command pays nothing for the hint.

    Raises:
        EffectParameterError: a parameter of an effect of ``phenomenon`` not in ``effects``.
    """
    try:
        yield
    except UnknownParameterError as exc:
        owners = effect_parameters(registry, phenomenon, effects)
        matches = fnmatch.filter(owners, exc.name)
        if not matches:
            raise
        raise EffectParameterError(exc.name, option, owners[matches[0]]) from None


def effect_parameters(registry: Registry, phenomenon: str, effects: Sequence[str] = ()) -> dict[str, str]:
    """Parameter name → effect, for the effects of ``phenomenon`` that are not in ``effects``."""
    owners: dict[str, str] = {}
    for name in registry.effects_of(phenomenon):
        if name in effects:
            continue
        try:
            space = registry.effect(name, phenomenon=phenomenon).parameter_space
        except PhysinferError:  # a broken plugin gives no hint; its own error shows elsewhere
            continue
        for spec in space:
            owners.setdefault(spec.name, name)
    return owners


def make_simulator(phenomenon: Any, effects: Sequence[Any], duration_s: float | None = None) -> Any:
    """The phenomenon's simulator with ``effects``, recording ``duration_s`` seconds when given.

    Raises:
        UserInputError: a duration that is not positive, or one the phenomenon cannot record.
    """
    if duration_s is None:
        return phenomenon.make_simulator(effects)
    if not duration_s > 0:
        raise UserInputError(f"--duration must be positive seconds, got {duration_s:g}")
    if not accepts_keyword(phenomenon.make_simulator, "duration_s"):
        raise UserInputError(
            f"--duration: the phenomenon {phenomenon.name!r} records a fixed length (its make_simulator "
            "takes no duration_s); drop --duration"
        )
    return phenomenon.make_simulator(effects, duration_s=duration_s)


def target_duration(pipeline: Pipeline, target: Target) -> float | None:
    """Seconds to simulate so that simulations span as long as ``target``, for a phenomenon
    that asks for it (``duration_from_target``); ``None`` otherwise.

    Capped at what the embedder reads (its ``config.n_frames`` or ``config.max_seconds``,
    where it has them).
    """
    if not pipeline.phenomenon.duration_from_target:
        return None
    seconds = target.clip.n_frames / float(target.clip.fps)
    config = getattr(pipeline.embedder, "config", None)
    frames = getattr(config, "n_frames", None)
    cap = frames / float(pipeline.embedder.fps) if frames else getattr(config, "max_seconds", None)
    return round(min(seconds, cap) if cap else seconds, 3)


def full_parameter_space(pipeline: Pipeline, fixed: Sequence[str]) -> ParameterSpace:
    """Every parameter of the pipeline's model, those ``--fix`` (``fixed``, its items) holds included.

    Only ``--fix``'s wrapper is looked through: parameters a phenomenon's own simulator
    holds fixed (the diagnose benchmark's ``flag_lite``) are not part of its model, so
    they are neither in a model file nor accepted by ``--truth``.
    """
    return (split_fixed(pipeline.simulator)[0] if fixed else pipeline.simulator).parameter_space


def fixed_by_user(pipeline: Pipeline, fixed: Sequence[str]) -> dict[str, float]:
    """The values ``--fix`` (``fixed``, its items) holds in ``pipeline``; ``{}`` without it.

    Only the wrapper ``--fix`` adds counts: a phenomenon whose own simulator holds some
    parameters fixed (the diagnose benchmark's ``flag_lite``) has not had them fixed by the user.
    """
    return split_fixed(pipeline.simulator)[1] if fixed else {}


# The noise floor: how far apart two realisations of the same θ are.


#: Salt of :func:`noise_seeds` unless another is given.
DEFAULT_SEED_SALT = 0x5EED


def noise_seeds(base_seed: int, n: int, *, salt: int = DEFAULT_SEED_SALT) -> list[int]:
    """``n`` distinct seeds derived from ``base_seed``, none equal to it.

    Re-simulation seeds must differ from the seed every trial of a refinement uses, or the
    "re-simulation" would repeat the trial's own clip. Another ``salt`` gives another,
    independent set (for re-simulations whose seeds must not repeat those of others).
    """
    if n <= 0:
        return []
    state = np.random.SeedSequence([int(base_seed), int(salt)]).generate_state(4 * n + 4, dtype=np.uint32)
    seeds: list[int] = []
    for value in (int(v) % (2**31 - 1) for v in state):
        if value != base_seed and value not in seeds:
            seeds.append(value)
        if len(seeds) == n:
            break
    return seeds


@dataclass
class NoiseFloor:
    """Distances among re-simulations of one θ, and from each to a target.

    Attributes:
        params: The θ re-simulated (physical values by name).
        seeds: The seeds of the successful re-simulations, in order.
        embeddings: ``(K, D)`` embeddings of the re-simulations.
        pairwise: ``K (K - 1) / 2`` squared distances between re-simulations (``i < j``).
        to_target: ``K`` squared distances from each re-simulation to the target, or
            ``None`` when no target was given.
        n_failed: Re-simulations that failed (not in the lists above).
    """

    params: dict[str, float]
    seeds: list[int]
    embeddings: np.ndarray = field(repr=False)
    pairwise: list[float]
    to_target: list[float] | None
    n_failed: int = 0

    @property
    def floor(self) -> float:
        """Median distance between two realisations of θ: the distance a perfect model has."""
        return float(np.median(self.pairwise)) if self.pairwise else float("nan")

    @property
    def floor_q95(self) -> float:
        """95th percentile of the pairwise distances (a one-sided threshold for "within noise")."""
        return float(np.quantile(self.pairwise, 0.95)) if self.pairwise else float("nan")

    @property
    def gap(self) -> float | None:
        """Median distance from a re-simulation to the target (``None`` without a target)."""
        return float(np.median(self.to_target)) if self.to_target else None

    def log_std(self) -> float:
        """Standard deviation of ``log D``: the per-observation noise of a log objective.

        Taken over the distances to the target when there are at least two, else over the
        pairwise ones; ``nan`` when there are fewer than two distances.
        """
        values = self.to_target if self.to_target and len(self.to_target) >= 2 else self.pairwise
        if len(values) < 2:
            return float("nan")
        return float(np.std(np.log(np.asarray(values) + 1e-12), ddof=1))

    def summary(self) -> dict[str, Any]:
        """JSON-compatible numbers (for ``result.json`` and reports)."""
        return {
            "floor": self.floor,
            "floor_q95": self.floor_q95,
            "gap": self.gap,
            "ratio": (self.gap / self.floor) if self.gap is not None and self.floor > 0 else None,
            "log_std": self.log_std(),
            "n": len(self.seeds),
            "n_failed": self.n_failed,
            "seeds": list(self.seeds),
            "pairwise": [float(d) for d in self.pairwise],
            "to_target": None if self.to_target is None else [float(d) for d in self.to_target],
        }


def _embed_here(
    pipeline: Pipeline, params: Mapping[str, float], zetas: Sequence[Mapping[str, Any]], seeds: Sequence[int]
) -> list[np.ndarray | None]:
    """Every seed's clip made in this process (``None``: its simulation failed)."""
    # One batch call (the flag simulates it in parallel threads); each clip is embedded on
    # its own, so the floor is bit for bit what one-at-a-time evaluation measures.
    simulated = simulate_many(pipeline.simulator, [params] * len(seeds), [int(s) for s in seeds])
    return [
        None if trajectory is None else np.asarray(pipeline.embedder.embed(pipeline.renderer.render(trajectory, zeta)))
        for zeta, (trajectory, _) in zip(zetas, simulated, strict=True)
    ]


def measure_noise_floor(
    pipeline: Pipeline,
    params: Mapping[str, float],
    render_params: Mapping[str, Any] | Sequence[Mapping[str, Any]],
    *,
    seeds: Sequence[int],
    target_embedding: np.ndarray | None = None,
    embed_clips: ClipEmbedder | None = None,
) -> NoiseFloor:
    """Re-simulate ``params`` under each seed, render, embed, and measure the distances.

    Args:
        pipeline: Simulator, renderer and embedder.
        params: θ, physical values by name.
        render_params: ζ for every re-render, or one ζ per seed (render variation).
        seeds: Simulation seeds (at least two; see :func:`noise_seeds`).
        target_embedding: ``(D,)`` embedding of the target, to also measure the gap.
        embed_clips: Make the clips there, all at once (one ζ only; the same numbers).

    Returns:
        The :class:`NoiseFloor`; failed re-simulations are counted, not raised.

    Raises:
        ValueError: for fewer than two seeds or a ζ list of the wrong length.
        SimulationFailed: when fewer than two re-simulations succeed.
    """
    if len(seeds) < 2:
        raise ValueError(f"a noise floor needs at least two seeds, got {len(seeds)}")
    zetas = [render_params] * len(seeds) if isinstance(render_params, Mapping) else list(render_params)
    if len(zetas) != len(seeds):
        raise ValueError(f"{len(zetas)} render-parameter sets for {len(seeds)} seeds")
    made = (
        embed_clips([params] * len(seeds), [int(s) for s in seeds])
        if embed_clips is not None and isinstance(render_params, Mapping)
        else _embed_here(pipeline, params, zetas, seeds)
    )
    embeddings, used, failed = [], [], 0
    for seed, embedding in zip(seeds, made, strict=True):
        if embedding is None:  # a failed re-simulation is a property of θ and this seed
            failed += 1
            continue
        embeddings.append(embedding)
        used.append(int(seed))
    if len(embeddings) < 2:
        raise SimulationFailed(f"only {len(embeddings)} of {len(seeds)} re-simulations succeeded")
    stacked = np.stack(embeddings)
    pairwise = [squared_distance(stacked[i], stacked[j]) for i, j in itertools.combinations(range(len(used)), 2)]
    to_target = None if target_embedding is None else [squared_distance(e, target_embedding) for e in stacked]
    return NoiseFloor(
        params={k: float(v) for k, v in params.items()},
        seeds=used,
        embeddings=stacked,
        pairwise=pairwise,
        to_target=to_target,
        n_failed=failed,
    )
