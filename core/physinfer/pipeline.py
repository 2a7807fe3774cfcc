"""Build a phenomenon's pipeline from the registry: its simulator (with effects and ``--fix``),
renderer and embedder.

Below the loop and every command: the session (:mod:`physinfer.session`), the trial workers
(which rebuild the pipeline in each worker process), the posterior and the diagnosis build
pipelines here; the video a pipeline is compared with is loaded by :mod:`physinfer.target`.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from physinfer.devices import check_device
from physinfer.errors import PhysinferError, UserInputError
from physinfer.evaluation import Pipeline
from physinfer.fixed import FixedParameters, resolve_fixed, split_fixed
from physinfer.parameters import (
    ParameterSpace,
    UnknownParameterError,
    refuse_repeats,
)
from physinfer.registry import Registry, accepts_keyword
from physinfer.roles import Target
from physinfer.scene import bind_scene, resolve_scene


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
