"""The diagnosis' settings: :class:`DiagnoseSettings` (everything a diagnosis needs besides
the registry) and the detection-limit ladder's :class:`LimitConfig`.

At the bottom of the package, below the workflow (:mod:`physinfer.discrepancy.workflow`, which
re-exports :class:`DiagnoseSettings`) and every stage that reads them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from physinfer.conditioning import Conditioning
from physinfer.discrepancy.decide import DecisionRule
from physinfer.discrepancy.localise import LocaliseConfig
from physinfer.errors import UserInputError
from physinfer.parameters import refuse_repeats
from physinfer.refinement import SearchSpec


@dataclass(frozen=True)
class LimitConfig:
    """Settings of the detection-limit ladder.

    Attributes:
        fractions: Rungs, as fractions of the way from off to the far end of the range.
        seeds: Fresh seeds per rung (one for a deterministic phenomenon).
        step: Forward-difference step of the Jacobian, in normalised coordinates.
        reveal: Also measure another view and a longer clip (chaotic phenomena; costly).
        budget_share: Most of the diagnosis's simulations the ladder may cost; fewer seeds
            per rung (at least two) are used to stay within it.
        search_check: Check each not-named candidate's limit with the diagnosis' own
            stages on a target made there (:mod:`physinfer.discrepancy.limit_check`; costly).
            Not part of the ladder's cache key: the check is kept apart.
    """

    fractions: tuple[float, ...] = (0.125, 0.25, 0.5, 1.0)
    seeds: int = 3
    step: float = 0.4
    reveal: bool = False
    budget_share: float = 0.2
    search_check: bool = False

    def to_dict(self) -> dict[str, Any]:
        """JSON form (part of the cache key)."""
        return {
            "fractions": list(self.fractions),
            "seeds": self.seeds,
            "step": self.step,
            "reveal": self.reveal,
            "budget_share": self.budget_share,
            # A new method invalidates a stored limits.json (2: each rung's own seed noise;
            # 3: a deterministic baseline's refits from the polish's Jacobian too, its rungs encoded).
            "method": 3,
        }


@dataclass(frozen=True)
class DiagnoseSettings:
    """Everything a diagnosis needs besides the registry.

    Attributes:
        plugin: Phenomenon name.
        out: Directory of the diagnosis (created; stages are sub-directories).
        target_path: Video to diagnose; ``None``: the phenomenon's embedded target.
        fps: Frame rate of ``target_path`` when the file does not say.
        truth: ``NAME=VALUE`` known values (reported, never used by the decisions).
        render_set: ζ overrides for the simulations.
        steps: Baseline budget (``None``: the phenomenon's default).
        effect_steps: Budget of the control and of each augmented model (``None``: ``steps``).
        optimizer: Registered optimizer name.
        embedder: Embedder name (``None``: the phenomenon's default).
        embedder_frames: Frames a parameter-free embedder reads (``None``: its default).
        duration_s: Seconds every simulation of every stage records (``None``: the
            phenomenon's default); see :func:`physinfer.evaluation.build_pipeline`.
        fixed: ``NAME=VALUE`` items (patterns allowed) held fixed in every model and left
            out of every search: values the user knows (see :mod:`physinfer.fixed`).
        weights: Embedder weights.
        device: torch device of the embedder.
        seed: Seed of optimizers and simulations.
        effects: Effects to try (empty: every effect registered for the phenomenon).
        floor_samples: ``K``, re-simulations per gap measurement (at least 4 for the rank test).
        select_top: Every stage re-simulates its best ``M`` trials under ``select_seeds``
            fresh seeds and keeps the lowest mean (0: the lowest logged distance; see
            :func:`physinfer.loop.select_best`). For chaotic phenomena it keeps the
            winner's curse out of every stage's best fit, the calibration runs' included.
        select_seeds: Fresh seeds per finalist.
        batch_size: Trials per optimizer step of every stage, simulated as one batch (see
            :class:`physinfer.refinement.SearchSpec`); ``None``: the phenomenon's
            ``diagnose_batch_size`` (:class:`physinfer.roles.Phenomenon`).
        calibrate: Run the self-consistency refinements (the null scale's optimizer part).
        calibration_runs: ``R``, self-consistency refinements; ``rule.calibration_summary``
            (the maximum by default) makes their gaps one (see :mod:`physinfer.discrepancy.decide`).
        calibrate_all: Refine every self-consistency run and control. By default only the
            runs that can change a decision are refined
            (:mod:`physinfer.discrepancy.self_consistency`): the decisions are the same,
            the null scale may then be known only as a range.
        calibration_control: Follow each calibration run with its own control
            (``effect_steps`` trials warm-started from its best θ), so that a self-consistency
            gap has the budget of the best baseline fit it is compared with; the
            misspecification test then uses that best fit's gap (``gap_before``) instead of
            the baseline stage's.
        rule: Decision thresholds.
        localise: Localisation settings.
        videos: Write the side-by-side video.
        limits: Estimate each candidate's detection limit (``detectable_from``).
        limit_config: The detection-limit ladder's settings (``reveal``: also try another
            view and a longer clip).
        screen: Leave out the candidates whose signature at the baseline's fit no fit could
            name, before they are refined (:mod:`physinfer.discrepancy.screen`).
        ridge_starts: Start each effect's search where the video points along the ridge it
            shares with the base parameters, not only at the baseline's fit
            (:mod:`physinfer.discrepancy.ridge`; ``False``: the baseline's fit alone); for
            a deterministic phenomenon also start every control and effect from its start polished
            towards its target (:func:`physinfer.discrepancy.stages.polished_starts`).
        scene_set: The scene's known settings (``--scene-set``; see :mod:`physinfer.scene`),
            bound to every model of the diagnosis and recorded in each stage's ``run.json``
            and in ``model.json``.
        workers: Local worker processes running the stages after the baseline side by side
            (``None``: one per CPU; 0 or 1: all in this process). The decisions do not
            depend on it.
        scheduler: A Dask scheduler address whose workers run those stages instead (they
            must have the plugins installed and see ``out``).
        progress: Draw a progress bar per stage on stderr.
        conditioning: How a ``target_path`` video is framed (:mod:`physinfer.conditioning`:
            a video that is not square is cropped to the renderer's framing, as ``refine``
            does; ``None``: used as it is). Recorded in the report (``target_conditions``).
        registry_factory: How a worker process builds the registry: a picklable callable
            returning one (``None``: the installed plugins, as
            :func:`physinfer.plugins.load_registry` finds them). Give one when the
            registry passed to :func:`run_diagnosis` holds phenomena registered in code.
    """

    plugin: str
    out: Path
    target_path: Path | None = None
    fps: float | None = None
    truth: tuple[str, ...] = ()
    render_set: Mapping[str, Any] = field(default_factory=dict)
    steps: int | None = None
    effect_steps: int | None = None
    optimizer: str = "ax"
    embedder: str | None = None
    embedder_frames: int | None = None
    duration_s: float | None = None
    fixed: tuple[str, ...] = ()
    weights: Path | None = None
    device: str | None = None
    seed: int = 0
    effects: tuple[str, ...] = ()
    floor_samples: int = 6
    select_top: int = 0
    select_seeds: int = 3
    batch_size: int | None = None
    calibrate: bool = True
    calibration_runs: int = 3
    calibrate_all: bool = False
    calibration_control: bool = True
    rule: DecisionRule = field(default_factory=DecisionRule)
    localise: LocaliseConfig = field(default_factory=LocaliseConfig)
    videos: bool = True
    limits: bool = True
    limit_config: LimitConfig = field(default_factory=LimitConfig)
    screen: bool = True
    ridge_starts: bool = True
    scene_set: Mapping[str, Any] = field(default_factory=dict)
    workers: int | None = None
    scheduler: str | None = None
    progress: bool = False
    conditioning: Conditioning | None = None
    registry_factory: Callable[[], Any] | None = None

    def validate(self) -> None:
        """Raise :class:`UserInputError` naming the first bad setting."""
        refuse_repeats(self.effects, "--effect")
        for name, value in (("--steps", self.steps), ("--effect-steps", self.effect_steps)):
            if value is not None and value < 1:
                raise UserInputError(f"{name} must be at least 1, got {value}")
        if self.floor_samples < 4:
            raise UserInputError(
                f"--floor-samples must be at least 4 (the rank test needs them), got {self.floor_samples}"
            )
        batch = 1 if self.batch_size is None else self.batch_size  # None: the phenomenon's, checked there
        SearchSpec(select_top=self.select_top, select_seeds=self.select_seeds, batch_size=batch).validate()
        if self.workers is not None and self.workers < 0:
            raise UserInputError(f"--workers must be 0 (in this process) or more, got {self.workers}")
        if self.calibration_runs < 1:
            raise UserInputError(
                f"--calibration-runs must be at least 1, got {self.calibration_runs} "
                "(use --no-calibrate to skip the self-consistency refinements)"
            )
        self.rule.validate()
        try:
            self.localise.validate()
        except ValueError as exc:
            raise UserInputError(f"localisation settings: {exc}") from None
