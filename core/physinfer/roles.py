"""The abstract roles of the refinement loop and the :class:`Phenomenon` record.

``θ → Simulator → Trajectory → Renderer(ζ) → Clip → Embedder → vector``; an
:class:`Optimizer` proposes θ in ``[-1, 1]^D`` and is told the embedding distance.
An :class:`Effect` is an optional physical term a phenomenon can switch into its
simulator; the discrepancy workflow ranks effects to name what a model is missing.

Plugins subclass these ABCs and register factories for them through the hooks in
:mod:`physinfer.hooks`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from physinfer.errors import UserInputError
from physinfer.parameters import ParameterSpace
from physinfer.scene import SceneSetting
from physinfer.types import Clip, Trajectory

Params = Mapping[str, float]


class Simulator(ABC):
    """θ → :class:`Trajectory`.

    Implementations must be deterministic for a given ``seed`` and must not keep state
    between calls that changes results. ``parameter_space`` lists every parameter the
    simulator accepts (for an augmented model: base plus effect parameters).
    """

    parameter_space: ParameterSpace

    @abstractmethod
    def simulate(self, params: Params, *, seed: int = 0) -> Trajectory:
        """Run one simulation.

        Args:
            params: Physical parameter values by name; must cover ``parameter_space``.
            seed: Seed for every random choice (initial perturbation, turbulence...).

        Returns:
            The trajectory, ``vertices`` of shape ``(T, V, 3)``.

        Raises:
            SimulationFailed: when the simulation blows up or produces NaN.
        """

    def simulate_batch(self, params: Sequence[Params], *, seeds: Sequence[int]) -> list[Trajectory]:
        """Run ``B`` simulations; the default loops, batched engines override it."""
        return [self.simulate(p, seed=s) for p, s in zip(params, seeds, strict=True)]


class Renderer(ABC):
    """:class:`Trajectory` + render parameters ζ → :class:`Clip`.

    ``default_render_params`` is the ζ used when none is given; ``sample_render_params``
    draws a varied ζ for dataset generation.
    """

    default_render_params: Mapping[str, Any] = {}

    @abstractmethod
    def render(self, trajectory: Trajectory, render_params: Mapping[str, Any] | None = None) -> Clip:
        """Render every frame of ``trajectory``; returns ``(T, H, W, 3)`` uint8 at its fps."""

    def sample_render_params(self, rng: np.random.Generator) -> dict[str, Any]:
        """A random ζ for dataset variety; the default is the fixed default ζ."""
        return dict(self.default_render_params)

    def check_render_params(self, render_params: Mapping[str, Any] | None) -> dict[str, Any]:
        """Validate ζ before any simulation runs; returns the complete ζ.

        The default accepts the keys of ``default_render_params`` (and anything when that
        is empty), and refuses what no renderer can use: a number that is not finite, or
        a value that is not a number where the default is one. Renderers override it to
        check types and ranges of their own (``size=0`` is finite but no image).

        Raises:
            UserInputError: naming an unknown key and the known ones, or the bad value.
        """
        given = dict(render_params or {})
        known = set(self.default_render_params)
        unknown = sorted(set(given) - known) if known else []
        if unknown:
            raise UserInputError(
                f"unknown render setting(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}"
            )
        for key, value in given.items():
            numeric = _is_number(self.default_render_params.get(key, value))
            if numeric and not (_is_number(value) and np.isfinite(value)):
                raise UserInputError(f"render setting {key}={value!r}: give a finite number")
        return {**self.default_render_params, **given}

    def close(self) -> None:  # noqa: B027 - optional hook, no-op by default
        """Release GPU/EGL resources (optional)."""


def _is_number(value: Any) -> bool:
    """A real number (``bool`` is not one: ``True`` is a switch, not a size)."""
    return isinstance(value, (int, float, np.number)) and not isinstance(value, (bool, np.bool_))


class Embedder(ABC):
    """:class:`Clip` → embedding vector of shape ``(D_e,)``.

    Attributes:
        fps: Frame rate the embedder expects; clips are resampled to it.
        n_frames: Number of frames it consumes; shorter clips are refused.
    """

    fps: float = 25.0
    n_frames: int = 30

    @abstractmethod
    def embed(self, clip: Clip) -> np.ndarray:
        """Embed one clip; returns a float vector ``(D_e,)``.

        Raises:
            UserInputError: when the clip is too short (fewer than ``n_frames`` after
                resampling to ``fps``).
        """

    def embed_many(self, clips: Sequence[Clip]) -> np.ndarray:
        """Embed several clips; returns ``(N, D_e)``."""
        return np.stack([self.embed(c) for c in clips])


@dataclass(frozen=True)
class Trial:
    """A point proposed by an optimizer.

    Attributes:
        index: The optimizer's trial index (unique within a run).
        x: ``(D,)`` coordinates in ``[-1, 1]^D``.
    """

    index: int
    x: np.ndarray


class Optimizer(ABC):
    """Ask/tell optimizer over ``[-1, 1]^D``, minimising, shaped like Ax's ``Client``.

    ``ask`` proposes trials, ``attach`` registers a point chosen elsewhere (the centre
    trial, or trials replayed on ``--resume``), ``tell`` reports a value (``None`` for a
    failed trial). Constructors take ``dim``, ``seed`` and ``names`` as keywords.
    """

    def __init__(self, *, dim: int, seed: int = 0, names: Sequence[str] | None = None) -> None:
        self.dim = dim
        self.seed = seed
        self.names = list(names) if names is not None else [f"x{i}" for i in range(dim)]

    @abstractmethod
    def ask(self, n: int = 1) -> list[Trial]:
        """Propose up to ``n`` new trials."""

    @abstractmethod
    def attach(self, x: np.ndarray) -> Trial:
        """Register the point ``x`` (shape ``(D,)``) as a trial to be told later."""

    @abstractmethod
    def tell(self, index: int, value: float | None, sem: float | None = None) -> None:
        """Report the objective of trial ``index``; ``None`` marks it failed.

        Args:
            index: The trial's index.
            value: The distance (lower is better), or ``None`` for a failed trial.
            sem: Standard error of ``value`` if known (noisy objectives).
        """


class Effect(ABC):
    """An optional physical effect a phenomenon can switch into its simulator.

    Attributes:
        name: Identifier, e.g. ``"wind_gusts"``.
        description: One physical line, e.g. "turbulent fluctuation of the wind speed".
        phenomenon: Name of the phenomenon whose simulator understands this effect.
        parameter_space: The effect's extra parameters, merged by the simulator into its
            own space (names unique across the phenomenon's parameters and every effect's).
            Each parameter's declared ``default`` is its "off" value: with every parameter
            at its default the augmented model reproduces the baseline, bit for bit
            (checked by :func:`physinfer.testing.check_effect`).
    """

    name: str
    description: str
    phenomenon: str
    parameter_space: ParameterSpace

    @abstractmethod
    def term(self, state: Any, params: Params, t: float) -> Any:
        """The extra term the simulator adds at time ``t`` (the simulator calls it, not the host).

        ``state`` and the return value are defined by the phenomenon's simulator (the
        pendulum passes ``(φ, φ', L)`` and adds the returned angular acceleration; the flag
        passes a ``WindState`` every 10 ms and keeps the one returned). ``params`` holds
        every parameter, the base ones and every effect's; ``t`` is in seconds.
        """


@dataclass(frozen=True)
class Target:
    """A video to refine against, with ground truth where known.

    Attributes:
        clip: The target video.
        truth: Physical parameter values that produced it, or ``None`` (real footage).
        render_params: The ζ to render simulations with (oracle ζ, as in the paper).
        description: Where the target came from.
        conditions: How a user's video was conditioned (framing found, ζ estimated; see
            :mod:`physinfer.conditioning`), or ``None``.
    """

    clip: Clip
    truth: dict[str, float] | None = None
    render_params: Mapping[str, Any] = field(default_factory=dict)
    description: str = ""
    conditions: dict[str, Any] | None = None

    @classmethod
    def synthetic(
        cls, simulator: Simulator, renderer: Renderer, truth: Params, *, seed: int, description: str
    ) -> Target:
        """A target simulated from ``truth`` under ``seed`` and rendered at the default ζ.

        The embedded default target of a phenomenon is usually one of these; the renderer
        is closed afterwards (its EGL context is not needed again).
        """
        zeta = dict(renderer.default_render_params)
        try:
            clip = renderer.render(simulator.simulate(truth, seed=seed), zeta)
        finally:
            renderer.close()
        return cls(clip=clip, truth=dict(truth), render_params=zeta, description=description)


@dataclass(frozen=True)
class Phenomenon:
    """Everything the host needs to refine one phenomenon.

    Attributes:
        name: Identifier used by ``--plugin``.
        description: One line.
        parameter_space: The refined parameters θ.
        make_simulator: ``(effects) -> Simulator``; ``effects`` is a sequence of
            :class:`Effect` to switch in (empty for the baseline model). A factory that
            also accepts the keyword ``duration_s`` (record at least that many seconds)
            lets datasets store clips longer than the simulator's default.
        make_renderer: ``() -> Renderer``.
        default_embedder: Name of a registered embedder used when none is chosen.
        default_target: ``() -> Target``: the embedded synthetic target.
        dataset_generator: Optional ``"module:attr"`` or callable building a dataset.
        effects: Names of effects registered for this phenomenon.
        default_steps: Refinement budget used when ``--steps`` is not given.
        default_steps_with_posterior: The budget when ``--steps`` is not given and the
            search starts from a posterior estimator's median and box (``None``:
            ``default_steps``). Starting where the video points, fewer trials do: on the
            flag, 16 trials from the shipped estimator beat 40 (docs/benchmarks.md).
        default_posterior: Path of a shipped posterior estimator (``physinfer posterior
            train``) used by ``infer`` and ``refine`` when none is given; ``None``: none.
        scene_posteriors: Paths of further shipped estimators, trained across ranges of
            scene settings (``dataset generate --scene-range``), told the camera
            (``posterior train --told-camera``) or on longer clips: when a target's scene
            (``--scene-set``) is not the default estimator's, the first that covers it is
            used; one told the camera only when ``--render-set`` tells it all; of those that
            answer, the one trained on the longest clips the video covers. Empty: none.
        framing: ``(box) -> square``: maps the box ``(x, y, w, h)`` in pixels of the
            region that moves in a video to the square ``(x, y, side, side)`` the
            renderer frames at its default ζ (``physinfer prepare``); ``None``:
            :func:`physinfer.framing.default_framing`, the box's centre with a margin.
        scene_settings: Known, non-inferred settings of the scene (a flag's size and
            pinning), :class:`physinfer.scene.SceneSetting` records the user sets with
            ``--scene-set NAME=VALUE``. A phenomenon that declares any must accept the
            keyword ``scene`` in ``make_simulator`` (and may in ``make_renderer``): the
            complete, validated settings by name, passed only when the user gave some
            (see :mod:`physinfer.scene`). Empty: ``--scene-set`` is refused.
        diagnose_batch_size: Trials per optimizer step in each of ``diagnose``'s refinements
            when ``--batch-size`` is not given. Where a trial costs little beside the
            optimizer's own step (the pendulum: 0.16 s to simulate, render and embed against
            0.5 s of Ax's GP fit and acquisition), 2 halves the GP fits; where simulating
            dominates (the flag), 1 keeps every search step informed by the last trial.
        nuisance: Names of θ entries that are nuisance parameters: what a real video leaves
            unknown but the physics does not care about (a pendulum's phase at the first
            frame). They are searched like the rest and reported apart (``result.json``
            ``nuisance``), never as a measurement.
        duration_from_target: Simulate as long as the target lasts when ``--duration`` is
            not given (the phenomenon's ``make_simulator`` must take ``duration_s``): for
            embedders that read a clip whole (``motion``), so a 25-s phone video is compared
            with 25-s simulations and a 2-s clip with 2-s ones.
        video_estimate: ``(clip) -> {name: (value, low, high)}``: what the target video
            tells directly, before any simulation (a pendulum's tracked period gives its
            length within the range its unknown amplitude allows). ``refine`` without a
            posterior estimator starts its search at these values and searches only
            ``[low, high]`` for them (the whole range for the others); ``None``: no estimate.
        facing: ``(clip) -> evidence``: which way round a video shows the subject, for a
            renderer that draws it one way round (the flag flies to the right): above 0 the
            renderer's way, below 0 mirrored, and ``|evidence| < 1`` cannot tell. A target
            read as mirrored is mirrored before it is compared (:mod:`physinfer.facing`);
            ``None``: the subject has no side (a pendulum) and videos are used as given.
    """

    name: str
    description: str
    parameter_space: ParameterSpace
    make_simulator: Callable[[Sequence[Effect]], Simulator]
    make_renderer: Callable[[], Renderer]
    default_embedder: str
    default_target: Callable[[], Target]
    dataset_generator: Any = None
    effects: tuple[str, ...] = ()
    default_steps: int = 40
    default_steps_with_posterior: int | None = None
    default_posterior: str | None = None
    scene_posteriors: tuple[str, ...] = ()
    framing: (
        Callable[[tuple[float, float, float, float]], tuple[float, float, float, float]] | None
    ) = None
    scene_settings: tuple[SceneSetting, ...] = ()
    # Last, so that records built with positional arguments keep their meaning.
    diagnose_batch_size: int = 1
    nuisance: tuple[str, ...] = ()
    duration_from_target: bool = False
    video_estimate: Callable[[Clip], dict[str, tuple[float, float, float]]] | None = None
    facing: Callable[[Clip], float] | None = None
