"""The protocol a phenomenon implements to have datasets generated: :class:`DatasetGenerator`.

A generator turns seeds into data: it samples θ for a simulation, simulates a batch of
them, samples ζ for each render and renders. The engine (:mod:`physinfer.datasets.engine`)
owns everything else: seeding, splits, work units, executors, files and resume.

Generators travel to worker processes (pickled with cloudpickle), so they must be small
and build their heavy parts (simulator, renderer, EGL context) lazily, inside the worker;
the worker keeps one unpickled generator per process and thread and reuses it for every
unit it runs. :class:`PhenomenonDatasetGenerator` builds a generator from any
:class:`~physinfer.roles.Phenomenon`; a plugin that wants other presets or a renderer
built at the stored size subclasses it and names it in ``Phenomenon.dataset_generator``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any

import numpy as np

from physinfer.datasets.presets import DEFAULT_PRESETS, ClipFormat, DatasetPreset
from physinfer.errors import UserInputError
from physinfer.parameters import ParameterSpace
from physinfer.registry import accepts_keyword, resolve
from physinfer.roles import Effect, Params, Phenomenon, Renderer, Simulator
from physinfer.scene import bind_scene, resolve_scene, sample_scene, scene_of
from physinfer.types import Clip, Trajectory


class DatasetGenerator(ABC):
    """Samples and produces the data of one phenomenon's dataset.

    Every random choice comes from the ``rng`` or ``seeds`` the engine passes in, so a
    dataset is a function of its seed. The engine converts whatever :meth:`render`
    returns to the stored :class:`ClipFormat` (resampling to its fps, keeping the first
    ``n_frames``, centre-crop and resize, grayscale); producing that format directly
    only saves work.

    Attributes:
        phenomenon: Name of the phenomenon (recorded in the dataset).
        parameter_space: The space θ is drawn from (recorded in the dataset).
    """

    phenomenon: str
    parameter_space: ParameterSpace
    #: Scene settings each simulation draws from a range (``--scene-range``); empty: one scene.
    scene_ranges: Mapping[str, tuple[float, float]] = MappingProxyType({})

    def presets(self) -> Mapping[str, DatasetPreset]:
        """The presets ``--preset`` chooses from; the default offers ``paper`` and ``cpu``."""
        return dict(DEFAULT_PRESETS)

    def sample_params(self, rng: np.random.Generator) -> dict[str, float]:
        """Draw θ for one simulation; the default is uniform in the normalised cube.

        Args:
            rng: The simulation's own generator (derived from the dataset seed).

        Returns:
            Physical values by name, every one within ``parameter_space``'s bounds.
        """
        return self.parameter_space.sample(rng, 1)[0]

    def sample_scene(self, rng: np.random.Generator) -> dict[str, float] | None:
        """Draw the ranged scene settings of one simulation (``None`` without ranges).

        Args:
            rng: The simulation's own scene generator (derived from the dataset seed).
        """
        if not self.scene_ranges:
            return None

        return sample_scene(rng, self.scene_ranges)

    def in_scene(self, scene: Mapping[str, float]) -> DatasetGenerator:
        """A generator that simulates and renders in ``scene`` (drawn by :meth:`sample_scene`).

        Raises:
            UserInputError: this generator cannot vary its scene.
        """
        raise UserInputError(
            f"the dataset generator {type(self).__name__} cannot vary its scene; drop --scene-range"
        )

    @abstractmethod
    def simulate_batch(
        self, params: Sequence[Params], seeds: Sequence[int], *, clip: ClipFormat
    ) -> list[Trajectory]:
        """Simulate ``B`` parameter sets (runs inside a worker).

        Args:
            params: ``B`` θ dicts from :meth:`sample_params`.
            seeds: ``B`` simulation seeds.
            clip: The stored format; simulating at least ``clip.n_frames`` frames at
                ``clip.fps`` avoids resampling.

        Returns:
            ``B`` trajectories, ``vertices`` of shape ``(T, V, 3)``.

        Raises:
            SimulationFailed: when a simulation blows up (the engine then retries the
                batch one simulation at a time and skips the ones that fail).
        """

    @abstractmethod
    def sample_render_params(self, rng: np.random.Generator) -> dict[str, Any]:
        """Draw ζ for one render (runs inside a worker); values must be JSON-compatible."""

    @abstractmethod
    def render(self, trajectory: Trajectory, render_params: Mapping[str, Any], *, clip: ClipFormat) -> Clip:
        """Render one clip (runs inside a worker).

        Args:
            trajectory: One simulation.
            render_params: ζ from :meth:`sample_render_params`.
            clip: The stored format, as a hint for the render size.

        Returns:
            A clip ``(T, H, W, C)`` uint8.
        """

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release renderer resources (called when a worker's generator is dropped)."""


class PhenomenonDatasetGenerator(DatasetGenerator):
    """The default generator of any phenomenon: its parameter space, simulator and renderer.

    θ is uniform in the normalised cube, ζ comes from ``Renderer.sample_render_params``,
    simulations run through ``Simulator.simulate_batch``. Plugins subclass it to change
    :meth:`presets` or to build the renderer at the stored size.

    Args:
        phenomenon: The phenomenon record (pickled to workers with its factories).
        effects: Effects switched into the simulator (none: the baseline model).
        presets: Presets offered instead of the defaults.
        scene_ranges: Scene settings each simulation draws from a range (validated by
            :func:`physinfer.scene.parse_scene_ranges`); the record's own scene (or the
            defaults) gives the rest.
    """

    def __init__(
        self,
        *,
        phenomenon: Phenomenon,
        effects: Sequence[Effect] = (),
        presets: Mapping[str, DatasetPreset] | None = None,
        scene_ranges: Mapping[str, tuple[float, float]] | None = None,
    ) -> None:
        self.record = phenomenon
        self.scene_ranges = {k: (float(a), float(b)) for k, (a, b) in (scene_ranges or {}).items()}
        self._scene_variant: tuple[str, PhenomenonDatasetGenerator] | None = None
        self.phenomenon = phenomenon.name
        self.effects = tuple(effects)
        self.parameter_space = phenomenon.parameter_space
        for effect in self.effects:
            self.parameter_space = self.parameter_space.merged(effect.parameter_space)
        self._presets = dict(presets) if presets is not None else None
        self._simulator: Simulator | None = None
        self._simulator_duration: float | None = None
        self._renderer: Renderer | None = None

    def __getstate__(self) -> dict[str, Any]:
        # Simulators and renderers (EGL contexts) never cross processes: rebuilt lazily.
        state = self.__dict__.copy()
        state["_simulator"] = None
        state["_renderer"] = None
        state["_scene_variant"] = None
        return state

    def in_scene(self, scene: Mapping[str, float]) -> PhenomenonDatasetGenerator:
        """This generator with its record bound to the record's scene updated by ``scene``.

        Only the last scene's generator is kept (each simulation has a scene of its own),
        the one before it closed, so renderers do not pile up; a simulation's renders
        follow one another and share it.
        """
        import json

        key = json.dumps(dict(scene), sort_keys=True)
        if self._scene_variant is not None and self._scene_variant[0] == key:
            return self._scene_variant[1]
        if self._scene_variant is not None:
            self._scene_variant[1].close()
        full = resolve_scene(self.record, {**(scene_of(self.record) or {}), **dict(scene)})
        variant = PhenomenonDatasetGenerator(
            phenomenon=bind_scene(self.record, full), effects=self.effects, presets=self._presets
        )
        self._scene_variant = (key, variant)
        return variant

    def presets(self) -> Mapping[str, DatasetPreset]:
        """The presets given at construction, else ``paper`` and ``cpu``."""
        return dict(self._presets) if self._presets is not None else super().presets()

    @property
    def simulator(self) -> Simulator:
        """The phenomenon's simulator, built on first use."""
        if self._simulator is None:
            self._simulator = self.record.make_simulator(self.effects)
        return self._simulator

    @property
    def renderer(self) -> Renderer:
        """The phenomenon's renderer, built on first use."""
        if self._renderer is None:
            self._renderer = self.record.make_renderer()
        return self._renderer

    def simulate_batch(
        self, params: Sequence[Params], seeds: Sequence[int], *, clip: ClipFormat
    ) -> list[Trajectory]:
        """``Simulator.simulate_batch`` of the phenomenon, recording the clip's duration when
        its ``make_simulator`` accepts ``duration_s`` (else its own frame count and rate)."""
        return self._simulator_for(clip).simulate_batch(params, seeds=seeds)

    def _simulator_for(self, clip: ClipFormat) -> Simulator:
        """The simulator that records at least ``clip``'s duration where the phenomenon allows."""
        if not accepts_keyword(self.record.make_simulator, "duration_s"):
            return self.simulator
        duration = clip.n_frames / clip.fps
        if self._simulator is None or self._simulator_duration != duration:
            self._simulator = self.record.make_simulator(self.effects, duration_s=duration)
            self._simulator_duration = duration
        return self._simulator

    def sample_render_params(self, rng: np.random.Generator) -> dict[str, Any]:
        """``Renderer.sample_render_params`` of the phenomenon."""
        return dict(self.renderer.sample_render_params(rng))

    def render(self, trajectory: Trajectory, render_params: Mapping[str, Any], *, clip: ClipFormat) -> Clip:
        """``Renderer.render`` of the phenomenon at its own size (the engine resizes)."""
        return self.renderer.render(trajectory, render_params)

    def close(self) -> None:
        """Close the renderer if one was built (and the last scene's)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._scene_variant is not None:
            self._scene_variant[1].close()
            self._scene_variant = None


def generator_for(
    phenomenon: Phenomenon,
    *,
    effects: Sequence[Effect] = (),
    scene_ranges: Mapping[str, tuple[float, float]] | None = None,
) -> DatasetGenerator:
    """The dataset generator of ``phenomenon``.

    ``Phenomenon.dataset_generator`` may hold a :class:`DatasetGenerator`, a factory
    called as ``factory(phenomenon=..., effects=...)`` (a subclass of
    :class:`PhenomenonDatasetGenerator` is one), or a ``"module:attr"`` reference to
    either; ``None`` gives :class:`PhenomenonDatasetGenerator`. ``scene_ranges``
    (``--scene-range``) go to a factory that takes them; other generators refuse them.

    Raises:
        UserInputError: when the reference cannot be imported or builds something else,
            or cannot vary the scene it is asked to.
    """
    spec = phenomenon.dataset_generator
    if spec is None:
        return PhenomenonDatasetGenerator(phenomenon=phenomenon, effects=effects, scene_ranges=scene_ranges)
    try:
        obj = resolve(spec)
    except (ImportError, AttributeError, ValueError) as exc:
        raise UserInputError(
            f"phenomenon {phenomenon.name!r}: cannot load its dataset generator {spec!r} "
            f"({type(exc).__name__}: {exc})"
        ) from None
    if not isinstance(obj, DatasetGenerator) and callable(obj):
        extra = {"scene_ranges": scene_ranges} if scene_ranges and accepts_keyword(obj, "scene_ranges") else {}
        obj = obj(phenomenon=phenomenon, effects=effects, **extra)
    if not isinstance(obj, DatasetGenerator):
        raise UserInputError(
            f"phenomenon {phenomenon.name!r}: dataset_generator {spec!r} gave "
            f"{type(obj).__name__}, not a physinfer.datasets.DatasetGenerator"
        )
    if scene_ranges and dict(obj.scene_ranges) != dict(scene_ranges):
        raise UserInputError(
            f"phenomenon {phenomenon.name!r}: its dataset generator {spec!r} cannot vary the scene; "
            "drop --scene-range"
        )
    return obj
