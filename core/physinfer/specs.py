"""What a refinement is asked, as four small frozen specs built once: what the model is
(:class:`ModelSpec`), what the target is (:class:`TargetSpec`), how to search
(:class:`~physinfer.refinement.SearchSpec`, the engine's record: the loop reads it as it is) and
how to execute (:class:`ExecutionSpec`), bundled as a :class:`RefineRequest`.

Each setting is declared once, as a field of one spec. The refine command's keywords are
those fields (:meth:`RefineRequest.from_keywords`); :mod:`physinfer.api` fills the specs from
:class:`~physinfer.api.RefineOptions` by name. ``default_budget``, once here, is
:func:`physinfer.refinement.default_budget` (found here with a warning).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from physinfer.conditioning import Conditioning
from physinfer.discrepancy.model import ModelFile, model_for_refine
from physinfer.errors import UserInputError
from physinfer.evaluation import Pipeline
from physinfer.moved import moved_names
from physinfer.pipeline import build_pipeline, naming_effects
from physinfer.refinement import SearchSpec
from physinfer.registry import Registry
from physinfer.roles import Target
from physinfer.rundir import RunDirectory
from physinfer.target import load_target
from physinfer.trial_workers import PipelineSpec, scene_items

__getattr__ = moved_names(__name__)


def _as_tuples(spec: Any, *names: str) -> None:
    """Store the sequences ``names`` of a frozen ``spec`` as tuples (callers pass lists)."""
    for name in names:
        object.__setattr__(spec, name, tuple(getattr(spec, name)))


@dataclass(frozen=True)
class ModelSpec:
    """What the model is: the phenomenon, its effects and held parameters, and how its
    clips are simulated and seen.

    Attributes:
        plugin: Phenomenon name.
        effects: Effects switched in (``--effect``).
        embedder: Embedder name (``None``: the phenomenon's default).
        weights: Embedder weights file (``None``: the shipped default).
        device: torch device of the embedder (``None``: CUDA when present, else CPU).
        fixed: ``NAME=VALUE`` items (patterns allowed) held fixed and left out of the
            search (``--fix``).
        duration_s: Seconds every simulation records (``None``: the phenomenon's default,
            or the target's length where the phenomenon takes it from the target).
        embedder_frames: Frames a parameter-free embedder reads (``None``: its default).
        scene_set: The scene's known settings (``--scene-set``; ``None``: the default scene).
        model_file: A model file written by ``physinfer diagnose`` (``--model``; the
            keyword ``model``): its effects are switched in and the search starts at its
            values (see :meth:`with_model_file`).
    """

    plugin: str
    effects: tuple[str, ...] = ()
    embedder: str | None = None
    weights: Path | None = None
    device: str | None = None
    fixed: tuple[str, ...] = ()
    duration_s: float | None = None
    embedder_frames: int | None = None
    scene_set: Mapping[str, Any] | None = None
    model_file: Path | None = None

    def __post_init__(self) -> None:
        _as_tuples(self, "effects", "fixed")

    def with_model_file(self) -> tuple[ModelSpec, ModelFile | None]:
        """This spec completed from its model file, and the file (``None`` without one).

        The file's effects are the model's; the clip length, held values and scene the
        diagnosis fitted it with (``diagnose --duration``, ``--fix``, ``--scene-set``) fill
        those this spec leaves unset.

        Raises:
            UserInputError: the file is missing, of another plugin, or names other effects.
        """
        if self.model_file is None:
            return self, None
        model = model_for_refine(self.model_file, self.plugin, self.effects)
        fitted = model.extra
        completed = replace(
            self,
            effects=model.effects,
            duration_s=fitted.get("duration_s") if self.duration_s is None else self.duration_s,
            fixed=self.fixed or tuple(f"{name}={value!r}" for name, value in fitted.get("fixed", {}).items()),
            scene_set=self.scene_set or fitted.get("scene") or {},
        )
        return completed, model

    def pipeline(self, registry: Registry) -> Pipeline:
        """The model's simulator, renderer and embedder (:func:`~physinfer.pipeline.build_pipeline`)."""
        return build_pipeline(
            registry, self.plugin, effects=self.effects, embedder=self.embedder, weights=self.weights,
            device=self.device, fixed=self.fixed, duration_s=self.duration_s,
            embedder_frames=self.embedder_frames, scene_set=self.scene_set,
        )  # fmt: skip

    def worker_spec(self, scene: Mapping[str, Any] | None) -> PipelineSpec:
        """What a trial worker rebuilds the simulator and renderer from (``scene``: the
        resolved scene, :func:`~physinfer.scene.scene_of`)."""
        return PipelineSpec(self.plugin, self.effects, self.fixed, duration_s=self.duration_s, scene=scene_items(scene))


@dataclass(frozen=True)
class TargetSpec:
    """What the target is: the video to match and what is known about it.

    Attributes:
        target_path: Video file (``--target``; ``None``: the phenomenon's own target).
        fps: Its frame rate when the file does not say.
        truth: Known true values ``NAME=VALUE``, for error reporting only.
        render_set: Render settings ζ of the simulations, ``{NAME: VALUE}`` (over the
            default or the camera estimated from the video).
        conditioning: How a ``target_path`` video is framed and its ζ estimated
            (:mod:`physinfer.conditioning`; ``None``: used as it is).
    """

    target_path: Path | None = None
    fps: float | None = None
    truth: tuple[str, ...] = ()
    render_set: Mapping[str, Any] | None = None
    conditioning: Conditioning | None = None

    def __post_init__(self) -> None:
        _as_tuples(self, "truth")

    def load(self, registry: Registry, pipeline: Pipeline, model: ModelSpec) -> Target:
        """The target, read (and conditioned) for ``pipeline`` (:func:`~physinfer.target.load_target`);
        a ``--truth`` of an effect's parameter names the effect."""
        with naming_effects(registry, model.plugin, model.effects, "--truth"):
            return load_target(
                pipeline, self.target_path, fps=self.fps, truth=self.truth, render_set=self.render_set or {},
                fixed=model.fixed, conditioning=self.conditioning,
            )  # fmt: skip


@dataclass(frozen=True)
class ExecutionSpec:
    """How to execute: the run directory (new, continued or replaced) and where the trials run.

    Attributes:
        out: The run directory.
        resume: Continue the run in ``out``.
        overwrite: Replace the run in ``out``.
        workers: Local worker processes for each step's trials (``None``: in this process;
            :mod:`physinfer.trial_workers`).
        scheduler: A Dask scheduler address for the trials.
    """

    out: Path
    resume: bool = False
    overwrite: bool = False
    workers: int | None = None
    scheduler: str | None = None

    def run_directory(self, target_path: Path | None) -> RunDirectory:
        """The run directory, checked before any work (:meth:`~physinfer.rundir.RunDirectory.check_out`).

        Raises:
            UserInputError: both ``resume`` and ``overwrite``, or an ``out`` the run may not write.
        """
        if self.resume and self.overwrite:
            raise UserInputError(
                "--resume continues the run in --out and --overwrite starts it again: give one of them"
            )
        run_dir = RunDirectory(self.out)
        run_dir.check_out(overwrite=self.overwrite, target=target_path)
        return run_dir


@dataclass(frozen=True)
class RefineRequest:
    """A refinement as its four specs, each built once (:meth:`from_keywords`, or
    :mod:`physinfer.api` from its options) and read by :func:`physinfer.session.run`.

    Attributes:
        model: What the model is.
        target: What the target is.
        search: How to search.
        execution: How to execute.
    """

    model: ModelSpec
    target: TargetSpec
    search: SearchSpec
    execution: ExecutionSpec

    @classmethod
    def from_keywords(cls, **settings: Any) -> RefineRequest:
        """Each keyword to the spec whose field it names (``model`` is
        :attr:`ModelSpec.model_file`); ``plugin`` and ``out`` are needed.

        Raises:
            TypeError: a keyword no spec declares, or ``plugin`` or ``out`` missing.
        """
        if "model" in settings:
            settings["model_file"] = settings.pop("model")
        specs: dict[str, Any] = {}
        for name, kind in _SPECS.items():
            names = {f.name for f in dataclasses.fields(kind)}
            specs[name] = kind(**{key: settings.pop(key) for key in list(settings) if key in names})
        if settings:
            raise TypeError(f"refine() got unexpected keyword arguments: {', '.join(sorted(settings))}")
        return cls(**specs)


#: The specs of a :class:`RefineRequest`, by its field names.
_SPECS: dict[str, type] = {"model": ModelSpec, "target": TargetSpec, "search": SearchSpec, "execution": ExecutionSpec}
