"""The settings of each command as one frozen dataclass, named as the CLI's options are.

``--batch-size`` is ``batch_size``, ``--render-set NAME=VALUE`` is ``render_set={NAME: VALUE}``,
a repeatable ``--effect`` is ``effects=(...)``. The options that ``simulate``, ``refine`` and
``diagnose`` share are declared once, in :class:`ModelOptions`, which the others extend; the
CLI builds these objects from its options and calls :mod:`physinfer.api`, so the command
line and the library cannot drift (``tests/core/test_api.py`` checks the mapping).
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from physinfer.api.values import Assignments, check_types
from physinfer.conditioning import Conditioning, parse_roi
from physinfer.errors import UserInputError
from physinfer.settings import check_counts, check_seed


@dataclass(frozen=True)
class ModelOptions:
    """What a model is and how its simulations are seen: shared by every command.

    Attributes:
        effects: Effects switched into the model (``--effect``).
        embedder: Embedder name (``None``: the phenomenon's default).
        weights: Embedder weights file (``None``: the shipped default).
        device: torch device (``None``: CUDA when present, else CPU).
        fix: Parameters held at known values and left out of the search:
            ``{NAME: VALUE}`` (NAME may be a pattern such as ``"bend_*"``) or ``NAME=VALUE`` strings.
        duration: Seconds every simulation records (``None``: the phenomenon's default).
        embedder_frames: Frames a parameter-free embedder reads (``None``: its default).
        render_set: Render settings ζ for the simulations, ``{NAME: VALUE}``.
        scene_set: The scene's known settings (e.g. the flag's size), ``{NAME: VALUE}``.
        seed: Seed of the optimizer and of every simulation.
    """

    effects: tuple[str, ...] = ()
    embedder: str | None = None
    weights: Path | None = None
    device: str | None = None
    fix: Assignments = field(default_factory=dict)
    duration: float | None = None
    embedder_frames: int | None = None
    render_set: Mapping[str, Any] = field(default_factory=dict)
    scene_set: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0


@dataclass(frozen=True)
class TargetOptions:
    """The video to match (shared by ``refine``, ``diagnose`` and ``infer``).

    Attributes:
        target: Video file (``None``: the phenomenon's embedded target).
        fps: Its frame rate when the file does not say.
        truth: Known true values, for error reporting only: ``{NAME: VALUE}`` or strings.
    """

    target: Path | None = None
    fps: float | None = None
    truth: Assignments = field(default_factory=dict)


@dataclass(frozen=True)
class FootageOptions:
    """How a ``target`` video is framed before it is compared (``refine``, ``infer``;
    :mod:`physinfer.conditioning`).

    Attributes:
        no_prepare: Use the video as it is (by default a video that is not square is framed
            as the renderer frames its subject, steadied and resampled, as ``physinfer
            prepare`` does).
        roi: ``"x,y,w,h"`` or four numbers: the region the subject moves in, in the video's
            pixels, instead of the one found.
        mirror: ``True``: the video shows the subject the other way round from the renderer
            (a flag flying left): mirror it first; ``False``: never mirror; ``None``: as the
            phenomenon reads the video (:mod:`physinfer.facing`).
        start: Seconds left out at the video's start (a hand letting go, a camera settling).
        end: Second of the video at which the part compared ends (``None``: its end).
    """

    no_prepare: bool = False
    roi: str | tuple[float, float, float, float] | None = None
    mirror: bool | None = None
    start: float = 0.0
    end: float | None = None

    def conditioning(self, *, estimate_render: bool = False) -> Conditioning:
        """The :class:`~physinfer.conditioning.Conditioning` these options ask for."""
        roi = parse_roi(self.roi) if isinstance(self.roi, str) else self.roi
        if roi is not None and len(roi) != 4:
            raise UserInputError(f"roi {roi!r}: give x, y, w, h in the video's pixels")
        return Conditioning(
            prepare=False if self.no_prepare else None,
            roi=None if roi is None else tuple(float(v) for v in roi),
            estimate_render=estimate_render,
            mirror=self.mirror,
            start_s=float(self.start),
            end_s=None if self.end is None else float(self.end),
        )


@dataclass(frozen=True)
class SearchOptions:
    """How a refinement searches (shared by ``refine`` and ``diagnose``).

    Attributes:
        steps: Trials in all (``None``: the phenomenon's default, or its
            ``default_steps_with_posterior`` when the search starts from a posterior estimator).
        optimizer: ``ax``, ``random``, ``cma`` or a plugin's.
        floor_samples: Re-simulations of the best fit for the noise floor.
        select_top: Re-simulate the best M trials under ``select_seeds`` fresh seeds and keep
            the lowest mean distance (0: the lowest logged distance).
        select_seeds: Fresh seeds per finalist.
        batch_size: Trials proposed per optimizer step and simulated as one batch.
    """

    steps: int | None = None
    optimizer: str = "ax"
    floor_samples: int = 4
    select_top: int = 0
    select_seeds: int = 3
    batch_size: int = 1


@dataclass(frozen=True)
class SimulateOptions(ModelOptions):
    """``physinfer simulate``.

    Attributes:
        set: Parameter values ``{NAME: VALUE}`` (the rest take their defaults).
        out: Video to write (``.mp4``/``.gif``); ``None``: none.
        trajectory_out: Trajectory NPZ to write (``.npz``); ``None``: none.
        overwrite: Replace ``out`` and ``trajectory_out`` when they exist (by default an
            existing file is refused before anything is simulated).
        render: Render the clip (``False``: the trajectory only).
    """

    set: Assignments = field(default_factory=dict)
    out: Path | None = None
    trajectory_out: Path | None = None
    overwrite: bool = False
    render: bool = True


@dataclass(frozen=True)
class RefineOptions(ModelOptions, TargetOptions, FootageOptions, SearchOptions):
    """``physinfer refine``.

    Attributes:
        out: Run directory (``None``: ``runs/<plugin>-<time>``).
        resume: Continue the run in ``out``.
        overwrite: Replace a finished run in ``out``.
        model: Model file from ``physinfer diagnose`` (its effects, warm-started from its fit).
        noise_samples: Re-simulations of the centre whose spread the optimizer is told.
        seeds_per_trial: Seeds each trial's distance is averaged over.
        workers: Local worker processes for each step's trials (``None``: in this process).
        scheduler: A Dask scheduler address for the trials.
        posterior: Posterior estimator file (``None``: the phenomenon's shipped one).
        no_posterior: Use no posterior estimator (a best fit only).
        no_render_estimate: Render simulations at the default ζ instead of the camera
            estimated from a ``target`` video (``render_set`` overrides either way).
    """

    out: Path | None = None
    resume: bool = False
    overwrite: bool = False
    model: Path | None = None
    noise_samples: int = 3
    seeds_per_trial: int = 1
    workers: int | None = None
    scheduler: str | None = None
    posterior: Path | None = None
    no_posterior: bool = False
    no_render_estimate: bool = False


@dataclass(frozen=True)
class DiagnoseOptions(ModelOptions, TargetOptions, FootageOptions, SearchOptions):
    """``physinfer diagnose``.

    Attributes:
        out: Diagnosis directory (``None``: ``runs/diagnose-<plugin>-<time>``); run again to continue.
        effect_steps: Trials per augmented model and for the control (``None``: ``steps``).
        floor_samples: Re-simulations per gap measurement (at least 4).
        calibrate: Run the self-consistency refinements that calibrate the null scale.
        calibration_runs: How many.
        calibrate_all: Refine every one of them; by default only those that could change a
            decision (the same decisions, the null scale then possibly only a range).
        calibration_control: Give each its own control, as the baseline has.
        calibration_summary: ``max`` or ``median`` of their gaps.
        threshold: The gap test finds the model misspecified above this many null scales.
        require_gap_test: Name an effect only when the gap test alone finds a misspecification.
        no_video: Skip the side-by-side video.
        limits: Estimate each effect's detection limit from a ladder of simulations.
        reveal: Also measure whether another view or a longer clip would lower the limits.
        check_limits: Check each not-named limit with this search (:mod:`~physinfer.discrepancy.limit_check`).
        screen: Leave out, before refining them, the candidates whose signature no fit could
            name on this target (:mod:`physinfer.discrepancy.screen`); ``False``: refine all.
        ridge_starts: Start each effect's search along its ridge too (:mod:`~physinfer.discrepancy.ridge`),
            and, for a deterministic phenomenon, every control's and effect's search from its start polished.
        workers: Local worker processes running the stages after the baseline side by side
            (``None``: one per CPU; 0 or 1: in this process).
        scheduler: A Dask scheduler address whose workers run those stages.
        batch_size: Trials proposed per optimizer step of every stage (``None``: the
            phenomenon's ``diagnose_batch_size``: 2 for the pendulum example, 1 for the flag).
    """

    out: Path | None = None
    batch_size: int | None = None
    effect_steps: int | None = None
    floor_samples: int = 6
    calibrate: bool = True
    calibration_runs: int = 3
    calibrate_all: bool = False
    calibration_control: bool = True
    calibration_summary: str = "max"
    threshold: float = 2.0
    require_gap_test: bool = False
    no_video: bool = False
    limits: bool = True
    reveal: bool = False
    check_limits: bool = False
    screen: bool = True
    ridge_starts: bool = True
    workers: int | None = None
    scheduler: str | None = None


@dataclass(frozen=True)
class InferOptions(TargetOptions, FootageOptions):
    """``physinfer infer``.

    Attributes:
        posterior: Estimator file (``None``: the phenomenon's shipped one).
        out: Directory for posterior.json, samples.npz and corner.png (``None``: ``runs/infer-<plugin>-<time>``).
        overwrite: Replace an earlier infer's results in ``out`` (only those; a folder of
            other files is refused whatever this says).
        samples: Posterior samples drawn.
        seed: Seed of the sampling.
        device: torch device.
        scene_set: The scene's known settings; an estimator trained on another scene is refused.
        render_set: The camera and light the video was taken with, ``{NAME: VALUE}``: an
            estimator told the camera (``render_inputs``) needs them all, and the phenomenon's
            shipped one is chosen when they are given.
        check: Simulate the posterior's median and say whether the model reproduces the video
            (``adequacy``; two simulations, seconds on the flag).
    """

    posterior: Path | None = None
    out: Path | None = None
    overwrite: bool = False
    samples: int = 5000
    seed: int = 0
    device: str | None = None
    scene_set: Mapping[str, Any] = field(default_factory=dict)
    render_set: Mapping[str, Any] = field(default_factory=dict)
    check: bool = True


@dataclass(frozen=True)
class PosteriorTrainOptions:
    """``physinfer posterior train``.

    Attributes:
        data: Dataset directory from ``physinfer dataset generate`` (θ stored with the clips),
            or several trained on together (generated alike: one phenomenon, clip format,
            parameter space and scene; ``--data A --data B``).
        out: Estimator file to write (``*.safetensors``; its configuration is stored inside).
        overwrite: Replace ``out`` when it exists (by default an existing file is refused
            before anything is embedded or trained).
        embedder: Embedder (``None``: the phenomenon's default).
        embedder_frames: Frames a parameter-free embedder reads (``None``: its default).
        weights: Embedder weights file (``None``: the shipped default).
        split: Dataset split to train on.
        density: Density estimator: ``nsf`` (neural spline flow), ``maf`` or ``mdn``.
        max_epochs: Upper bound on training epochs.
        patience: Stop after this many epochs without a better validation loss.
        seed: Seed of the networks' initialisation and batches.
        ensemble: Flows trained with seeds ``seed .. seed + ensemble - 1``; the posterior is
            their mixture.
        device: torch device (``None``: CUDA when present, else CPU).
        stored: Train on the stored renders as they are, instead of the clips as users
            give videos (camera effects, H.264 and ``infer``'s conditioning; the default).
        render_inputs: Render settings (camera, light) the estimator is told, each clip's
            from the dataset; ``infer`` then needs them (``render_set``).
        told_camera: Tell it every numeric render setting the dataset varies.
        accept_miscalibrated: Write an estimator that fails its held-out check (its
            intervals miss the truth too often or collapse), with the check recorded.
    """

    data: Path | tuple[Path, ...] | None = None
    out: Path | None = None
    overwrite: bool = False
    embedder: str | None = None
    embedder_frames: int | None = None
    weights: Path | None = None
    split: str = "train"
    density: str = "nsf"
    max_epochs: int = 400
    patience: int = 60
    seed: int = 0
    ensemble: int = 1
    device: str | None = None
    stored: bool = False
    render_inputs: tuple[str, ...] = ()
    told_camera: bool = False
    accept_miscalibrated: bool = False


@dataclass(frozen=True)
class CalibrationOptions:
    """``physinfer evaluate calibration``.

    Attributes:
        data: Dataset of held-out simulations.
        posterior: Estimator file (``None``: the phenomenon's shipped one).
        split: Dataset split to check on.
        samples: Posterior samples per simulation (at least 50).
        seed: Seed of the posterior samples.
        out: Directory for calibration.json and calibration.png (``None``:
            ``runs/calibration-<plugin>-<time>``).
        overwrite: Replace an earlier calibration's results in ``out`` (only those).
        device: torch device.
    """

    data: Path | None = None
    posterior: Path | None = None
    split: str = "test"
    samples: int = 1000
    seed: int = 0
    out: Path | None = None
    overwrite: bool = False
    device: str | None = None


@dataclass(frozen=True)
class PrepareOptions:
    """``physinfer prepare``.

    Attributes:
        target: Video to prepare (mp4/mov/..., gif or an image folder).
        out: Prepared video (``.mp4``/``.gif``); ``NAME.json`` and ``NAME_overlay.png`` go
            beside it (``None``: nothing written; the prepared clip is returned).
        overwrite: Replace ``out``, ``NAME.json`` and ``NAME_overlay.png`` when they exist (by
            default any of them existing is refused before the video is read).
        roi: ``"x,y,w,h"`` or four numbers in the input's pixels: the region the subject
            moves in, instead of the one found.
        fps: Frame rate of ``target`` when the file does not say.
        embedder: Embedder whose frame rate and input size to prepare for (``None``: the
            phenomenon's).
        size: Side of the square output in pixels (``None``: the embedder's).
        start: Seconds trimmed from the start.
        end: Second of ``target`` at which the part kept ends (``None``: its end), as
            ``refine``, ``infer`` and ``diagnose`` read ``end``.
        duration: Seconds kept from ``start`` (``None``: to the end); another way to say
            ``end`` (giving both is refused).
        no_stabilise: Do not measure or remove camera shake.
        no_freeze: Keep the flicker of pixels that do not move (by default they are set to
            their temporal median, as a renderer draws a static background).
        no_render_estimate: Do not estimate the camera's render parameters ζ.
        mirror: ``True``: mirror the video first (it shows the subject the other way round
            from the renderer); ``False``: never; ``None``: as the phenomenon reads it.
    """

    target: Path | None = None
    out: Path | None = None
    overwrite: bool = False
    roi: str | tuple[float, float, float, float] | None = None
    fps: float | None = None
    embedder: str | None = None
    size: int | None = None
    start: float = 0.0
    end: float | None = None
    duration: float | None = None
    no_stabilise: bool = False
    no_freeze: bool = False
    no_render_estimate: bool = False
    mirror: bool | None = None


@dataclass(frozen=True)
class RenderOptions:
    """``physinfer render``: draw a trajectory file with a phenomenon's renderer.

    Attributes:
        trajectory: Trajectory NPZ (``simulate --trajectory-out``, a run's
            ``best_trajectory.npz``) or a folder of per-frame ``.obj`` meshes in physinfer's
            frame (metres, z up, wind along +x).
        out: Video to write (``.mp4``/``.gif``; ``None``: none, the clip is returned).
        overwrite: Replace ``out`` when it exists (by default an existing file is refused
            before anything is rendered).
        fps: Frame rate of the trajectory: required for OBJ folders, overrides an NPZ's.
        render_set: Render settings ζ, ``{NAME: VALUE}``.
        scene_set: The scene's settings (the flag's ``pole_height`` draws a pole for meshes
            that carry none), ``{NAME: VALUE}``.
    """

    trajectory: Path | None = None
    out: Path | None = None
    overwrite: bool = False
    fps: float | None = None
    render_set: Mapping[str, Any] = field(default_factory=dict)
    scene_set: Mapping[str, Any] = field(default_factory=dict)


Options = TypeVar(
    "Options",
    SimulateOptions,
    RefineOptions,
    DiagnoseOptions,
    InferOptions,
    PosteriorTrainOptions,
    CalibrationOptions,
    PrepareOptions,
    RenderOptions,
)


def with_settings(
    kind: type[Options], options: Options | None, settings: Mapping[str, Any]
) -> Options:
    """``options`` (default: ``kind()``) with ``settings`` replacing its fields.

    Raises:
        UserInputError: an options object of another command, a setting ``kind`` lacks
            (naming the closest one), a ``seed`` outside 0..2**32-1, or a count of
            :data:`physinfer.settings.COUNT_LIMITS` (``samples``, ``embedder_frames``) out of range.
    """
    base = kind() if options is None else options
    if not isinstance(base, kind):
        raise UserInputError(f"options: expected {kind.__name__}, got {type(base).__name__}")
    names = [f.name for f in dataclasses.fields(kind)]
    for name in settings:
        if name not in names:
            close = difflib.get_close_matches(name, names, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise UserInputError(f"{kind.__name__} has no setting {name!r}{hint}")
    merged = dataclasses.replace(base, **settings)
    if "seed" in names:  # as the CLI checks every command's --seed
        check_seed(merged.seed)  # type: ignore[attr-defined]
    check_counts(merged)  # --steps, --samples, --embedder-frames, ...: before any work
    check_types(merged)
    if getattr(merged, "roi", None) is not None and "target" in names and merged.target is None:  # type: ignore[attr-defined]
        raise UserInputError(
            "--roi: give --target too; a region is in the pixels of your video (the phenomenon's own target "
            "needs none)"
        )
    return merged
