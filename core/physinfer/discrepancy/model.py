"""The model file: which effects a phenomenon's model switches in, and where to start.

``physinfer diagnose`` writes it; ``physinfer refine --model FILE`` reads it to refine
the augmented model, warm-started from the values the diagnosis found. JSON::

    {"format": "physinfer-model/1", "plugin": "pendulum_lab", "effects": ["quadratic_drag"],
     "parameters": [... ParameterSpace.to_dict() ...], "values": {"length": 1.2, ...},
     "gap": 0.41, "source": "runs/diag/effect-quadratic_drag"}
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from physinfer.errors import UserInputError
from physinfer.io import atomic_write_json
from physinfer.parameters import ParameterSpace
from physinfer.scene import same_scene, scene_text

MODEL_FORMAT = "physinfer-model/1"


@dataclass(frozen=True)
class ModelFile:
    """A phenomenon's model with effects switched in and its warm-start values.

    Attributes:
        plugin: Phenomenon name.
        effects: Effect names to switch in (empty: the baseline model).
        parameters: The model's full parameter space as written (for checking).
        values: Physical values to warm-start from, by name.
        extra: Anything else stored (gap, source run).
    """

    plugin: str
    effects: tuple[str, ...]
    parameters: list[dict[str, Any]]
    values: dict[str, float]
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The JSON object."""
        return {
            "format": MODEL_FORMAT,
            "plugin": self.plugin,
            "effects": list(self.effects),
            "parameters": self.parameters,
            "values": dict(self.values),
            **self.extra,
        }

    def start_for(self, space: ParameterSpace) -> dict[str, float]:
        """The warm-start values checked against ``space`` (the rebuilt model's).

        Raises:
            UserInputError: when the model's parameters no longer match the plugin's.
        """
        if sorted(space.names) != sorted(self.values):
            raise UserInputError(
                f"the model file's parameters {sorted(self.values)} do not match the {self.plugin!r} model "
                f"with effects {list(self.effects)} ({sorted(space.names)}); re-run physinfer diagnose"
            )
        return space.complete({n: min(max(v, space[n].bounds[0]), space[n].bounds[1]) for n, v in self.values.items()})


def write_model(
    path: Path, *, plugin: str, effects: Sequence[str], space: ParameterSpace, values: Mapping[str, float], **extra: Any
) -> ModelFile:
    """Write a model file atomically and return it."""
    model = ModelFile(plugin, tuple(effects), space.to_dict(), {k: float(v) for k, v in values.items()}, dict(extra))
    atomic_write_json(path, model.to_dict())
    return model


def read_model(path: Path) -> ModelFile:
    """Read a model file.

    Raises:
        UserInputError: when the file is missing, not JSON or not a model file.
    """
    path = Path(path)
    if not path.is_file():
        raise UserInputError(f"--model {path}: no such file (physinfer diagnose writes model.json in its --out)")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise UserInputError(f"--model {path} is not JSON ({exc}); give the model.json physinfer diagnose wrote") from None
    if not isinstance(data, dict) or data.get("format") != MODEL_FORMAT:
        raise UserInputError(f"--model {path} is not a physinfer model file (expected format {MODEL_FORMAT!r})")
    try:
        known = {"format", "plugin", "effects", "parameters", "values"}
        return ModelFile(
            plugin=str(data["plugin"]),
            effects=tuple(str(e) for e in data["effects"]),
            parameters=list(data["parameters"]),
            values={str(k): float(v) for k, v in data["values"].items()},
            extra={k: v for k, v in data.items() if k not in known},
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise UserInputError(f"--model {path} is incomplete or malformed ({exc})") from None


def model_for_refine(path: Path, plugin: str, effects: Sequence[str]) -> ModelFile:
    """Read a model file for ``physinfer refine --model`` and check it fits the request.

    Raises:
        UserInputError: when the file is for another plugin, or ``--effect`` names
            effects other than the file's.
    """
    model = read_model(path)
    if model.plugin != plugin:
        raise UserInputError(f"--model {path} is a model of {model.plugin!r}, not of --plugin {plugin!r}")
    if effects and sorted(effects) != sorted(model.effects):
        raise UserInputError(
            f"--effect {list(effects)} contradicts --model {path} (effects {list(model.effects)}); drop --effect"
        )
    return model


def check_model_scene(model: ModelFile, path: Path, phenomenon: Any, scene: Mapping[str, Any] | None) -> None:
    """Refuse to refine ``model`` on a scene other than the one its values were fitted on.

    Raises:
        UserInputError: ``--scene-set`` names another scene than ``model.json`` records
            (no ``scene`` there: the phenomenon's defaults).
    """
    fitted = model.extra.get("scene")
    if not same_scene(phenomenon, scene, fitted):
        raise UserInputError(
            f"--model {path} was fitted on {scene_text(fitted)}, but this refinement's scene is "
            f"{scene_text(scene)}; drop --scene-set (the model's scene is used) or diagnose again on this scene"
        )

