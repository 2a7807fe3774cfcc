"""physinfer as a library: every command of the CLI as a function returning a result object.

::

    import physinfer

    sim = physinfer.simulate("pendulum_lab", set={"length": 1.2})
    result = physinfer.refine("pendulum_lab", steps=20, out="runs/pendulum")
    result.best_params, result.posterior, result.to_dict(), result.plot()

(The package re-exports the commands and their options: ``physinfer.refine`` is
``physinfer.api.refine``. The loop itself is :mod:`physinfer.loop`, the diagnosis
:mod:`physinfer.discrepancy`.)

The keyword arguments are the CLI's options (``--batch-size`` is ``batch_size``,
``--render-set NAME=VALUE`` is ``render_set={NAME: VALUE}``); each command's settings are one
frozen dataclass (:class:`RefineOptions`, ...) that may also be passed whole, with keywords
replacing its fields. The CLI is a thin shell over these functions. Nothing is printed:
``progress=True`` shows rich progress bars on stderr, and a callable receives progress.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from physinfer.api.footage import PreparedVideo, Rendering, prepare, render
from physinfer.api.options import (
    CalibrationOptions,
    DiagnoseOptions,
    FootageOptions,
    InferOptions,
    ModelOptions,
    PosteriorTrainOptions,
    PrepareOptions,
    RefineOptions,
    RenderOptions,
    SearchOptions,
    SimulateOptions,
    TargetOptions,
    with_settings,
)
from physinfer.api.plugins import registry
from physinfer.api.results import Diagnosis, Simulation
from physinfer.api.values import as_assignments, as_names, required
from physinfer.discrepancy.decide import DecisionRule
from physinfer.discrepancy.settings import DiagnoseSettings, LimitConfig
from physinfer.discrepancy.workflow import run_diagnosis
from physinfer.errors import UserInputError
from physinfer.evaluation import build_pipeline, naming_effects
from physinfer.io import check_output_file
from physinfer.outputs import OutputFolder
from physinfer.parameters import parse_float_assignments
from physinfer.progress import StageProgress
from physinfer.refinement import RefineResult, SearchSpec
from physinfer.scene import scene_of
from physinfer.session import ExecutionSpec, ModelSpec, RefineRequest, TargetSpec
from physinfer.session import run as run_refine
from physinfer.video import write_video

if TYPE_CHECKING:  # their modules import torch and sbi: imported when the function runs
    from physinfer.posterior.calibrate_workflow import CalibrationReport
    from physinfer.posterior.infer_workflow import PosteriorReport
    from physinfer.posterior.train_workflow import TrainResult

__all__ = [
    "CalibrationOptions",
    "DiagnoseOptions",
    "Diagnosis",
    "FootageOptions",
    "InferOptions",
    "ModelOptions",
    "PosteriorTrainOptions",
    "PrepareOptions",
    "PreparedVideo",
    "RefineOptions",
    "RenderOptions",
    "Rendering",
    "SearchOptions",
    "SimulateOptions",
    "Simulation",
    "TargetOptions",
    "diagnose",
    "evaluate_calibration",
    "infer",
    "prepare",
    "refine",
    "registry",
    "render",
    "simulate",
    "train_posterior",
]

#: What ``infer`` writes into its ``--out`` (the folder's manifest lists them; ``--overwrite``
#: removes them and nothing else).
INFER_OUTPUTS = ("posterior.json", "samples.npz", "corner.png", "report.html")
#: What ``evaluate calibration`` writes into its ``--out``.
CALIBRATION_OUTPUTS = ("calibration.json", "calibration.png")

#: ``progress``: ``True`` for rich bars on stderr, or ``(done, total, best_distance) -> None``.
Progress = bool | Callable[[int, int, float], None]


def _optional(path: Path | str | None) -> Path | None:
    return None if path is None else Path(path)


def _default_out(prefix: str) -> Path:
    return Path("runs") / f"{prefix}-{time.strftime('%Y%m%d-%H%M%S')}"


def simulate(plugin: str, options: SimulateOptions | None = None, **settings: Any) -> Simulation:
    """Simulate a phenomenon once and render it (``physinfer simulate``).

    Args:
        plugin: The phenomenon.
        options: All settings at once; ``settings`` replace its fields.
        **settings: Fields of :class:`SimulateOptions` (``set``, ``effects``, ``render_set``,
            ``seed``, ``duration``, ``out``, ``trajectory_out``, ``overwrite``, ...).

    Raises:
        UserInputError: an unknown parameter, render setting or effect; a bad output path
            (an existing file without ``overwrite``, a ``trajectory_out`` not ``*.npz``, a
            folder that cannot be written), refused before anything is simulated.
    """
    o = with_settings(SimulateOptions, options, settings)
    effects = as_names(o.effects, "effects")
    out, trajectory_out = _optional(o.out), _optional(o.trajectory_out)
    _check_simulate_outputs(out, trajectory_out, overwrite=o.overwrite)
    pipeline = build_pipeline(
        registry(), plugin, effects=effects, embedder="", duration_s=o.duration, scene_set=o.scene_set
    )
    with naming_effects(
        registry(), plugin, effects, "--set"
    ):  # an effect's parameter: name the effect
        params = pipeline.simulator.parameter_space.complete(
            parse_float_assignments(as_assignments(o.set, "set"))
        )
    render = o.render or out is not None
    # Check ζ before simulating: a typo should not cost a simulation.
    zeta = pipeline.renderer.check_render_params(
        {**pipeline.renderer.default_render_params, **o.render_set}
    )
    t0 = time.perf_counter()
    trajectory = pipeline.simulator.simulate(params, seed=o.seed)
    sim = Simulation(
        plugin, params, effects, o.seed, trajectory, seconds={"simulate": time.perf_counter() - t0}
    )
    sim.scene = scene_of(pipeline.phenomenon)
    if trajectory_out is not None:
        trajectory.save(trajectory_out)
        sim.paths["trajectory"] = str(trajectory_out)
    if render:
        t1 = time.perf_counter()
        sim.clip, sim.render_params = pipeline.renderer.render(trajectory, zeta), zeta
        sim.seconds["render"] = time.perf_counter() - t1
    if out is not None:
        write_video(out, sim.clip)
        sim.paths["video"] = str(out)
    pipeline.renderer.close()
    return sim


def _check_simulate_outputs(
    out: Path | None, trajectory_out: Path | None, *, overwrite: bool
) -> None:
    """Refuse outputs ``simulate`` must not write, before it simulates (two names for one
    file cannot pass: one must end ``.mp4``/``.gif``, the other ``.npz``)."""
    if out is not None:
        if out.suffix.lower() not in (".mp4", ".gif"):
            raise UserInputError(f"--out {out}: write a .mp4 or .gif file")
        check_output_file(out, "--out", overwrite=overwrite)
    if trajectory_out is not None:
        check_output_file(
            trajectory_out, "--trajectory-out", overwrite=overwrite, suffixes=(".npz",),
            what="the trajectory file",
        )  # fmt: skip


def refine(
    plugin: str,
    options: RefineOptions | None = None,
    *,
    progress: Progress = False,
    **settings: Any,
) -> RefineResult:
    """Refine a simulation until it matches a video (``physinfer refine``).

    Args:
        plugin: The phenomenon.
        options: All settings at once; ``settings`` replace its fields.
        progress: ``True`` for a rich progress bar on stderr, or a callable
            ``(done, total, best_distance)`` called after every trial.
        **settings: Fields of :class:`RefineOptions` (``target``, ``steps``, ``batch_size``,
            ``fix``, ``render_set``, ``out``, ``resume``, ...).

    Returns:
        The :class:`~physinfer.refinement.RefineResult`: ``best_params``, ``posterior`` (the
        90 % intervals and identifiability labels, when an estimator applies), the files
        written to ``run_dir``, ``to_dict()`` and ``plot()``.
    """
    o = with_settings(RefineOptions, options, settings)
    if o.resume and o.out is None:
        raise UserInputError("--resume needs --out DIR (the run directory to continue)")
    return run_refine(registry(), _refine_request(plugin, o), progress=progress)


def _refine_request(plugin: str, options: RefineOptions) -> RefineRequest:
    """The refine command's specs (:mod:`physinfer.session`) from its options: each field
    copied from the option of its name, except those named or converted here."""
    o = options
    return RefineRequest(
        model=_spec(
            ModelSpec, o, plugin=plugin, effects=as_names(o.effects, "effects"), weights=_optional(o.weights),
            fixed=as_assignments(o.fix, "fix"), duration_s=o.duration, model_file=_optional(o.model),
        ),
        target=_spec(
            TargetSpec, o, target_path=_optional(o.target), truth=as_assignments(o.truth, "truth"),
            render_set=dict(o.render_set), conditioning=o.conditioning(estimate_render=not o.no_render_estimate),
        ),
        search=_spec(SearchSpec, o, posterior=_optional(o.posterior), use_posterior=not o.no_posterior),
        execution=_spec(ExecutionSpec, o, out=_optional(o.out) or _default_out(plugin)),
    )  # fmt: skip


_Spec = TypeVar("_Spec")


def _spec(kind: type[_Spec], options: Any, **given: Any) -> _Spec:
    """A ``kind`` spec: ``given``, and each of its other fields the option of the same name;
    a field no option declares (the search's ``noise_sem``, ``log_objective``: the engine's
    own) keeps the spec's default."""
    names = [f.name for f in dataclasses.fields(kind) if f.name in given or hasattr(options, f.name)]  # type: ignore[arg-type]
    return kind(**{name: given[name] if name in given else getattr(options, name) for name in names})


def diagnose(
    plugin: str,
    options: DiagnoseOptions | None = None,
    *,
    log: Callable[[str], None] | None = None,
    progress: bool = False,
    **settings: Any,
) -> Diagnosis:
    """Find where the refined model disagrees with the video and name the missing effect
    (``physinfer diagnose``).

    Args:
        plugin: The phenomenon.
        options: All settings at once; ``settings`` replace its fields.
        log: Called with one line per stage (``None``: silent).
        progress: Draw a progress bar per stage on stderr.
        **settings: Fields of :class:`DiagnoseOptions`.
    """
    o = with_settings(DiagnoseOptions, options, settings)
    out = _optional(o.out) or _default_out(f"diagnose-{plugin}")
    diagnose_settings = DiagnoseSettings(
        plugin=plugin,
        out=out,
        target_path=_optional(o.target),
        fps=o.fps,
        truth=as_assignments(o.truth, "truth"),
        render_set=dict(o.render_set),
        steps=o.steps,
        effect_steps=o.effect_steps,
        optimizer=o.optimizer,
        embedder=o.embedder,
        embedder_frames=o.embedder_frames,
        duration_s=o.duration,
        fixed=as_assignments(o.fix, "fix"),
        weights=_optional(o.weights),
        device=o.device,
        seed=o.seed,
        effects=as_names(o.effects, "effects"),
        floor_samples=o.floor_samples,
        select_top=o.select_top,
        select_seeds=o.select_seeds,
        batch_size=o.batch_size,
        calibrate=o.calibrate,
        calibration_runs=o.calibration_runs,
        calibrate_all=o.calibrate_all,
        calibration_control=o.calibration_control,
        rule=DecisionRule(
            misspecified_factor=o.threshold,
            calibration_summary=o.calibration_summary,
            effect_evidence=not o.require_gap_test,
        ),
        videos=not o.no_video,
        limits=o.limits,
        limit_config=LimitConfig(reveal=o.reveal, search_check=o.check_limits),
        screen=o.screen,
        ridge_starts=o.ridge_starts,
        scene_set=dict(o.scene_set),
        conditioning=o.conditioning(),  # framing a wide video; ζ stays the default or --render-set
        workers=o.workers,
        scheduler=o.scheduler,
        progress=progress,
    )
    report = run_diagnosis(registry(), diagnose_settings, log=log)
    return Diagnosis.from_report(report, out)


def infer(plugin: str, options: InferOptions | None = None, **settings: Any) -> PosteriorReport:
    """The posterior of one video from an amortized estimator, in seconds (``physinfer infer``).

    Args:
        plugin: The phenomenon.
        options: All settings at once; ``settings`` replace its fields.
        **settings: Fields of :class:`InferOptions` (``target``, ``posterior``, ``samples``, ...).

    Returns:
        The :class:`~physinfer.posterior.workflow.PosteriorReport`: ``marginals`` (median,
        50 % and 90 % intervals, label per parameter), ``to_dict()`` and ``plot()``.
    """
    from physinfer.posterior.workflow import infer as run  # torch, sbi

    o = with_settings(InferOptions, options, settings)
    out = _optional(o.out) or _default_out(f"infer-{plugin}")
    with OutputFolder(out, "infer", INFER_OUTPUTS, example="infer").writing(overwrite=o.overwrite):
        return run(
            registry(),
            plugin=plugin,
            out=out,
            target_path=_optional(o.target),
            posterior=_optional(o.posterior),
            fps=o.fps,
            truth=as_assignments(o.truth, "truth"),
            n_samples=o.samples,
            seed=o.seed,
            device=o.device,
            scene_set=o.scene_set,
            render_set=dict(o.render_set),
            check=o.check,
            conditioning=o.conditioning(),
        )


#: ``progress`` of a staged job: ``True`` for rich bars on stderr, or ``(stage, done, total) -> None``.
StagedProgress = bool | Callable[[str, int, int], None]


@contextlib.contextmanager
def _staged_progress(progress: StagedProgress) -> Iterator[Callable[[str, int, int], None]]:
    """The ``(stage, done, total)`` callback ``progress`` asks for."""
    if callable(progress):
        yield progress
        return
    with StageProgress(bool(progress)) as bars:
        yield bars.update


def train_posterior(
    plugin: str,
    options: PosteriorTrainOptions | None = None,
    *,
    progress: StagedProgress = False,
    **settings: Any,
) -> TrainResult:
    """Train an amortized posterior q(θ | s(x)) on a dataset (``physinfer posterior train``).

    The dataset's clips are embedded once (cached beside it) and sbi's NPE is trained on the
    (θ, embedding) pairs; the estimator file loads without unpickling code.

    Args:
        plugin: The phenomenon.
        options: All settings at once; ``settings`` replace its fields.
        progress: ``True`` for rich bars on stderr (embedding, training), or a callable
            ``(stage, done, total)``.
        **settings: Fields of :class:`PosteriorTrainOptions` (``data`` and ``out`` are needed;
            an existing ``out`` is replaced only with ``overwrite``).

    Returns:
        The :class:`~physinfer.posterior.train_workflow.TrainResult`: ``estimator``, ``path``,
        ``to_dict()`` and ``plot()`` (the validation loss per epoch).
    """
    from physinfer.posterior.estimator import NetworkConfig  # torch
    from physinfer.posterior.train_workflow import train_posterior as run

    o = with_settings(PosteriorTrainOptions, options, settings)
    if o.data is None:  # a directory, or several (--data A --data B): the workflow checks them
        required(o.data, "data", "the dataset directory (physinfer dataset generate)")
    out = required(o.out, "out", "the estimator file to write (*.safetensors)")
    # Before the embedding and training (minutes to hours): the user's weights stay theirs.
    check_output_file(
        out, "--out", overwrite=o.overwrite, suffixes=(".safetensors",), what="the estimator file"
    )
    network = NetworkConfig(
        density=o.density, max_epochs=o.max_epochs, stop_after_epochs=o.patience, ensemble=o.ensemble
    )
    with _staged_progress(progress) as report:
        return run(
            registry(), plugin=plugin, data=o.data, out=out, embedder=o.embedder,
            embedder_frames=o.embedder_frames, weights=_optional(o.weights), device=o.device,
            split=o.split, network=network, seed=o.seed, as_given=not o.stored,
            accept_miscalibrated=o.accept_miscalibrated, render_inputs=as_names(o.render_inputs, "render_inputs"),
            told_camera=o.told_camera, progress=report,
        )  # fmt: skip


def evaluate_calibration(
    plugin: str,
    options: CalibrationOptions | None = None,
    *,
    progress: StagedProgress = False,
    **settings: Any,
) -> CalibrationReport:
    """Simulation-based calibration of a posterior estimator on held-out simulations
    (``physinfer evaluate calibration``): rank histograms and the coverage of its 50 % and
    90 % intervals, per parameter.

    Args:
        plugin: The phenomenon.
        options: All settings at once; ``settings`` replace its fields.
        progress: ``True`` for rich bars on stderr (embedding, sampling), or a callable
            ``(stage, done, total)``.
        **settings: Fields of :class:`CalibrationOptions` (``data`` is needed).

    Returns:
        The :class:`~physinfer.posterior.calibrate_workflow.CalibrationReport`: coverage,
        ranks, median errors and contraction per parameter, ``to_dict()`` and ``plot()``.
    """
    from physinfer.posterior.calibrate_workflow import evaluate_calibration as run  # torch, sbi

    o = with_settings(CalibrationOptions, options, settings)
    data = required(o.data, "data", "a dataset of held-out simulations (physinfer dataset generate)")
    out = _optional(o.out) or _default_out(f"calibration-{plugin}")
    folder = OutputFolder(out, "evaluate calibration", CALIBRATION_OUTPUTS, example="calibration")
    with folder.writing(overwrite=o.overwrite), _staged_progress(progress) as report:
        return run(
            registry(), plugin=plugin, data=data, out=out,
            posterior=_optional(o.posterior), split=o.split, n_samples=o.samples, seed=o.seed,
            device=o.device, progress=report,
        )  # fmt: skip
