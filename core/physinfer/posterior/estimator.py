"""An amortized posterior q(θ | s(x)) trained with sbi's NPE, saved and loaded safely.

θ is learnt in the normalised coordinates of the phenomenon's parameter space, where the
prior is uniform on ``[-1, 1]^D`` (the distribution ``physinfer dataset generate`` draws θ
from); samples are mapped back to physical units by the space.

File format (one ``.safetensors`` file, no pickles anywhere):

- the density estimator's ``state_dict`` as safetensors tensors;
- metadata ``physinfer``: the JSON :class:`EstimatorConfig` (plugin, embedder and its frames,
  the embedding of a fixed probe clip, clip length, parameter space, prior, network);
- metadata ``digest``: sha256 over the tensors and the config, so an edited file is refused.

Loading rebuilds the network from the config with sbi's builder and loads the tensors
into it (``strict``); nothing in the file is executed.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from physinfer.devices import check_device
from physinfer.errors import UserInputError
from physinfer.io import atomic_path
from physinfer.moved import moved_names
from physinfer.parameters import ParameterSpace
from physinfer.posterior.fingerprint import PROBE_TOLERANCE, embedder_probe, probe_mismatch
from physinfer.posterior.flows import build_network, to_unit
from physinfer.posterior.inputs import check_inputs, render_context, render_outside
from physinfer.scene import default_scene, same_scene, scene_context, scene_remedy, scene_text

FORMAT_NAME = "physinfer-posterior"
FORMAT_VERSION = 1
DENSITY_MODELS = ("maf", "nsf", "mdn")

#: The flows' names read here before they moved to :mod:`physinfer.posterior.flows` (warns).
__getattr__ = moved_names(__name__)


@dataclass(frozen=True)
class NetworkConfig:
    """The conditional density estimator (sbi's ``posterior_nn``) and how it is trained.

    Attributes:
        density: ``"maf"`` (masked autoregressive flow), ``"nsf"`` (neural spline flow) or
            ``"mdn"`` (mixture density network).
        hidden_features: Width of the flow's networks.
        num_transforms: Flow layers.
        batch_size: Training batch size.
        learning_rate: Adam's step size.
        max_epochs: Upper bound on epochs (training stops earlier once the validation loss
            has not improved for ``stop_after_epochs``).
        stop_after_epochs: Patience of the early stop.
        validation_fraction: Share of the pairs held out for the early stop.
        ensemble: Flows trained independently (seeds ``seed .. seed + ensemble - 1``, each
            with its own validation split); the posterior is their equal-weight mixture, as
            sbi's ``NeuralPosteriorEnsemble``. On the flag's 800 clips one flow's wind error
            varies by ±0.05 m/s with its seed; five average that out.
    """

    density: str = "nsf"
    hidden_features: int = 64
    num_transforms: int = 5
    batch_size: int = 50
    learning_rate: float = 1e-3
    max_epochs: int = 400
    stop_after_epochs: int = 60
    validation_fraction: float = 0.1
    ensemble: int = 1

    def validate(self) -> None:
        """Raise :class:`UserInputError` on settings sbi cannot use."""
        if self.density not in DENSITY_MODELS:
            raise UserInputError(
                f"--density {self.density!r}: choose one of {', '.join(DENSITY_MODELS)}"
            )
        for name in (
            "hidden_features",
            "num_transforms",
            "batch_size",
            "max_epochs",
            "stop_after_epochs",
            "ensemble",
        ):
            if int(getattr(self, name)) < 1:
                raise UserInputError(
                    f"{name.replace('_', '-')} must be at least 1, got {getattr(self, name)}"
                )
        if not 0 < self.learning_rate < 1:
            raise UserInputError(f"learning rate must lie in (0, 1), got {self.learning_rate}")
        if not 0 < self.validation_fraction < 0.5:
            raise UserInputError(
                f"validation fraction must lie in (0, 0.5), got {self.validation_fraction}"
            )

    def builder(self) -> Callable[..., Any]:
        """sbi's builder of this network, called with a batch ``(theta, x)``."""
        from sbi.neural_nets import posterior_nn

        return posterior_nn(
            model=self.density,
            hidden_features=self.hidden_features,
            num_transforms=self.num_transforms,
        )


@dataclass(frozen=True)
class EstimatorConfig:
    """What an estimator was trained for; written into its file and checked on load.

    Attributes:
        plugin: Phenomenon name.
        embedder: Embedder name the summaries ``s(x)`` come from.
        embedder_frames: Frames the embedder reads (its ``n_frames``).
        embedder_fps: Frame rate the embedder resamples to.
        probe: Embedding of :func:`~physinfer.posterior.fingerprint.probe_clip` by that embedder: a fingerprint that tells
            another embedder (or other weights) apart at inference.
        clip_seconds: Length of the training clips; a shorter target cannot be embedded alike.
        parameters: The parameter space (``ParameterSpace.to_dict()``).
        x_dim: Input dimension: the embedding's ``E``, plus one per ranged scene setting and
            one per told render setting.
        network: The density estimator's settings.
        prior: The prior θ was drawn from; the flow models ``atanh`` of the normalised θ.
        training: How it was trained (dataset, pairs, epochs, losses, seed), informative.
        frames_option: ``--embedder-frames`` as given at training (``None``: the embedder's
            own), passed again when the embedder is rebuilt for inference.
        weights: ``--weights`` as given at training (``None``: the plugin's shipped ones).
        scene: The scene settings of the training dataset (``dataset generate
            --scene-set``; ``None``: the phenomenon's default scene). A target of another
            scene is not given this estimator's intervals (:meth:`PosteriorEstimator.check_scene`).
        scene_ranges: ``{name: [low, high]}``: scene settings the training clips varied
            (``dataset generate --scene-range``); the estimator takes them as inputs after
            the embedding (:meth:`PosteriorEstimator.condition`) and accepts targets within
            the ranges. ``None``: trained on one scene.
        targets: How the training clips reached the embedder: ``{"as_given": {camera,
            seed}}`` (through a camera, H.264 and ``infer``'s conditioning,
            :mod:`physinfer.as_given`) or ``None`` (the stored renders as they are).
        inputs: The training inputs' range per dimension (``low``/``high``: 0.1 and 99.9 %
            quantiles, ``mean``, ``std``, ``constant``: dimensions that never varied), from
            which :meth:`PosteriorEstimator.input_check` tells a target the estimator was not
            trained for; ``None`` for estimators older than the check.
        held_out: The check ``posterior train`` made on held-out clips as given
            (:mod:`physinfer.posterior.held_out`), or ``None``.
        render_inputs: ``{name: [low, high]}``: render settings ζ (the camera, the light)
            the estimator takes as inputs after the scene settings (``posterior train
            --render-input``), each scaled from the training clips' range to ``[-1, 1]``
            (:func:`physinfer.posterior.inputs.render_context`); ``infer`` needs them all
            (``--render-set``). ``None``: it averages over the training clips' ζ (absent
            from the files of such estimators, which are written as before).
    """

    plugin: str
    embedder: str
    embedder_frames: int
    embedder_fps: float
    probe: list[float]
    clip_seconds: float
    parameters: list[dict[str, Any]]
    x_dim: int
    network: NetworkConfig = field(default_factory=NetworkConfig)
    prior: dict[str, Any] = field(
        default_factory=lambda: {
            "kind": "uniform",
            "coordinates": "normalised",
            "low": -1.0,
            "high": 1.0,
            "flow_on": "atanh",
        }
    )
    training: dict[str, Any] = field(default_factory=dict)
    frames_option: int | None = None
    weights: str | None = None
    scene: dict[str, Any] | None = None
    scene_ranges: dict[str, list[float]] | None = None
    targets: dict[str, Any] | None = None
    inputs: dict[str, Any] | None = None
    held_out: dict[str, Any] | None = None
    render_inputs: dict[str, list[float]] | None = None

    @property
    def parameter_space(self) -> ParameterSpace:
        """The parameter space θ lives in."""
        return ParameterSpace.from_dict(self.parameters)

    @property
    def embedding_dim(self) -> int:
        """``E``: the embedding's share of :attr:`x_dim` (the rest are scene and render settings)."""
        return self.x_dim - len(self.scene_ranges or {}) - len(self.render_inputs or {})

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        d = asdict(self)
        if d["render_inputs"] is None:  # an estimator told no ζ is written byte for byte as before
            del d["render_inputs"]
        d["format"], d["version"] = FORMAT_NAME, FORMAT_VERSION
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> EstimatorConfig:
        """Inverse of :meth:`to_dict`; raises :class:`KeyError`/:class:`TypeError` on a bad dict."""
        body = {k: v for k, v in d.items() if k not in ("format", "version")}
        body["network"] = NetworkConfig(**body.get("network", {}))
        return cls(**body)


class PosteriorEstimator:
    """q(θ | s(x)): draws posterior samples of θ given an embedding.

    Args:
        config: What the estimator is for.
        network: sbi's trained conditional density estimator (``torch.nn.Module``).
        device: Torch device it lives on.
    """

    def __init__(
        self, config: EstimatorConfig, network: torch.nn.Module, device: str = "cpu"
    ) -> None:
        self.config = config
        self.network = network.to(device).eval()
        self.device = device
        #: Validation loss per epoch of each flow, when trained in this process (not saved).
        self.validation_curves: list[list[float]] = []

    @property
    def parameter_space(self) -> ParameterSpace:
        """The parameter space θ lives in."""
        return self.config.parameter_space

    def condition(
        self,
        embedding: np.ndarray,
        scene: Mapping[str, Any] | None,
        render: Mapping[str, Any] | None = None,
    ) -> np.ndarray:
        """``(x_dim,)`` what to sample at: the embedding, then the ranged scene settings of
        ``scene`` (a complete scene; only read when the estimator was trained across ranges),
        then the told render settings ``render`` (the user's ``--render-set``; only read when
        the estimator takes render inputs).

        Raises:
            UserInputError: a scene or render setting the estimator takes is not given.
        """
        x = np.asarray(embedding, dtype=np.float32).reshape(-1)
        ranges = self.config.scene_ranges
        if ranges:
            if scene is None or any(name not in scene for name in ranges):
                raise UserInputError(
                    f"this posterior estimator takes the scene settings {', '.join(sorted(ranges))}; give "
                    "them with --scene-set"
                )
            x = np.concatenate([x, np.asarray(scene_context(ranges, scene), dtype=np.float32)])
        told = self.config.render_inputs
        if told:
            self.check_render(render)
            x = np.concatenate([x, np.asarray(render_context(told, render or {}), dtype=np.float32)])
        return x

    def check_render(self, render: Mapping[str, Any] | None) -> None:
        """Refuse to answer without every render setting the estimator takes.

        Raises:
            UserInputError: naming the missing settings, their training ranges and how to
                give them, or to use an estimator that averages over the camera.
        """
        told = self.config.render_inputs or {}
        missing = sorted(name for name in told if name not in (render or {}))
        if not missing:
            return
        spans = ", ".join(f"{name} (trained on {told[name][0]:.3g}..{told[name][1]:.3g})" for name in missing)
        raise UserInputError(
            f"this posterior estimator is told the camera and light and needs {len(told)} render "
            f"setting{'s' if len(told) > 1 else ''}; not given: {spans}",
            remedy="give each with --render-set NAME=VALUE (the values the video was taken with), or use an "
            "estimator that averages over the camera (the plugin's default: drop --posterior)",
        )

    def render_outside(self, render: Mapping[str, Any] | None) -> list[str]:
        """The told render settings outside the training clips' ranges
        (:func:`physinfer.posterior.inputs.render_outside`; empty for an estimator told none)."""
        return render_outside(self.config.render_inputs, render or {})

    def input_check(self, x: np.ndarray) -> tuple[np.ndarray, dict[str, Any] | None]:
        """``(x, record)``: the estimator's input checked against its training inputs
        (:func:`physinfer.posterior.inputs.check_inputs`; ``record`` is ``None`` for an
        estimator trained before the check)."""
        return check_inputs(self.config.inputs, x)

    def sample_unit(self, x: np.ndarray, n: int, *, seed: int = 0) -> np.ndarray:
        """``(n, D)`` posterior samples in normalised coordinates for one embedding ``(E,)``."""
        return self.sample_unit_batched(np.asarray(x, dtype=np.float32)[None], n, seed=seed)[:, 0]

    def sample_unit_batched(self, xs: np.ndarray, n: int, *, seed: int = 0) -> np.ndarray:
        """``(n, B, D)`` samples for ``B`` embeddings ``(B, E)`` at once (calibration)."""
        x = self._check_x(np.asarray(xs, dtype=np.float32))
        with torch.random.fork_rng(), torch.no_grad():  # the caller's torch RNG is left as it was
            torch.manual_seed(seed)
            phi = self.network.sample((n,), condition=x)  # (n, B, D), unbounded
        return to_unit(phi.cpu().numpy().astype(np.float64))

    def _check_x(self, x: np.ndarray) -> torch.Tensor:
        if x.ndim != 2 or x.shape[1] != self.config.x_dim:
            raise UserInputError(
                f"embedding of dimension {x.shape[-1]} given to an estimator trained on {self.config.x_dim}: "
                f"embed with {self.config.embedder!r} reading {self.config.embedder_frames} frames"
            )
        if not np.isfinite(x).all():
            raise UserInputError(
                "the target's embedding is not finite (NaN or inf): the video may be blank, static or "
                "damaged; check it plays and shows the phenomenon"
            )
        return torch.from_numpy(x).to(self.device)

    def save(self, path: str | Path) -> Path:
        """Write the estimator as one safetensors file, atomically."""
        from safetensors.torch import save

        path = Path(path)
        tensors = {k: v.detach().cpu().contiguous() for k, v in self.network.state_dict().items()}
        config_json = json.dumps(self.config.to_dict(), sort_keys=True)
        metadata = {"physinfer": config_json, "digest": _digest(tensors, config_json)}
        with atomic_path(path, suffix=".safetensors") as tmp:
            tmp.write_bytes(
                save(tensors, metadata=metadata)
            )  # into the temp file, keeping its mode
        return path

    @classmethod
    def load(cls, path: str | Path, device: str = "cpu") -> PosteriorEstimator:
        """Read an estimator written by :meth:`save`, refusing damaged or edited files.

        Raises:
            UserInputError: the file is missing, not an estimator, or does not match its digest.
        """
        from safetensors import safe_open

        path = Path(path)
        if not path.is_file():
            raise UserInputError(
                f"posterior estimator {path} does not exist; train one with `physinfer posterior train`"
            )
        try:
            with safe_open(str(path), framework="pt", device="cpu") as f:
                metadata = f.metadata() or {}
                tensors = {k: f.get_tensor(k) for k in f.keys()}  # noqa: SIM118 - safe_open has no items()
        except Exception as exc:  # safetensors raises its own error types for malformed files
            raise UserInputError(
                f"{path} is not a readable posterior estimator file ({exc})"
            ) from None
        config_json = metadata.get("physinfer")
        if config_json is None:
            raise UserInputError(
                f"{path} is a safetensors file but not a physinfer posterior estimator"
            )
        if metadata.get("digest") != _digest(tensors, config_json):
            raise UserInputError(
                f"{path} has been modified since it was written (its digest does not match); "
                "re-train it with `physinfer posterior train`"
            )
        try:
            raw = json.loads(config_json)
            if raw.get("format") != FORMAT_NAME or raw.get("version") != FORMAT_VERSION:
                raise UserInputError(
                    f"{path}: format {raw.get('format')!r} version {raw.get('version')!r} is not "
                    f"{FORMAT_NAME!r} version {FORMAT_VERSION}; re-train it with this physinfer"
                )
            config = EstimatorConfig.from_dict(raw)
        except (KeyError, TypeError, ValueError) as exc:
            raise UserInputError(f"{path}: damaged estimator configuration ({exc})") from None
        network = build_network(config)
        try:
            network.load_state_dict(tensors, strict=True)
        except RuntimeError as exc:
            raise UserInputError(
                f"{path}: the weights do not fit the network its configuration names ({exc})"
            ) from None
        return cls(config, network, device)

    def check_for(
        self, plugin: str, parameter_space: ParameterSpace, path: str | Path = ""
    ) -> None:
        """Refuse an estimator made for another phenomenon or parameter space.

        Raises:
            UserInputError: naming what differs and how to get a matching estimator.
        """
        where = f"{path} " if path else ""
        if self.config.plugin != plugin:
            raise UserInputError(
                f"the posterior estimator {where}was trained for --plugin {self.config.plugin}, not {plugin}",
                remedy=f"train one for {plugin} with `physinfer posterior train --plugin {plugin}`",
            )
        mine, theirs = self.parameter_space, parameter_space
        if mine.to_dict() != theirs.to_dict():
            diff = _space_difference(mine, theirs)
            raise UserInputError(
                f"the posterior estimator {where}was trained on another parameter space ({diff})",
                remedy="train one on a dataset of this model (same effects, nothing --fix'ed)",
            )

    def check_scene(
        self, phenomenon: Any, scene: Mapping[str, Any] | None, path: str | Path = ""
    ) -> None:
        """Refuse a target of another scene than the training clips' (``None``: the default).

        Its embeddings were learnt from clips of one scene only: a flag of another size flaps
        at other frequencies in the same wind, so the estimator's intervals would be confident
        and wrong (docs/real-videos.md, "Flag size and pinning").

        Raises:
            UserInputError: naming both scenes and how to get a matching estimator.
        """
        ranges = self.config.scene_ranges or {}
        where = f"{path} " if path else ""
        if ranges:
            defaults = default_scene(phenomenon)
            full = {**defaults, **(scene or {})}
            outside = [
                f"{name}={float(full[name]):g} (trained on {low:g}..{high:g})"
                for name, (low, high) in sorted(ranges.items())
                if not low - 1e-9 <= float(full[name]) <= high + 1e-9
            ]
            fixed = {k: v for k, v in full.items() if k not in ranges}
            trained = {k: v for k, v in {**defaults, **(self.config.scene or {})}.items() if k not in ranges}
            if not outside and fixed == trained:
                return
            why = "; ".join(outside) if outside else f"its other settings were {scene_text(trained)}"
            raise UserInputError(
                f"the posterior estimator {where}does not cover this scene ({why})",
                remedy=scene_remedy(phenomenon, scene),
            )
        if same_scene(phenomenon, self.config.scene, scene):
            return
        trained, given = (
            scene_text(s) if not s else f"the scene {scene_text(s)}"
            for s in (self.config.scene, scene)
        )
        raise UserInputError(
            f"the posterior estimator {where}was trained on clips of {trained}, not of {given}",
            remedy=scene_remedy(phenomenon, scene),
        )

    def check_embedder(self, embedder: Any) -> None:
        """Refuse an embedder whose fingerprint differs from the one the estimator was trained with."""
        mismatch = probe_mismatch(self.config.probe, embedder_probe(embedder))
        if mismatch > PROBE_TOLERANCE:
            raise UserInputError(
                f"the embedder {self.config.embedder!r} here embeds differently from the one the estimator "
                f"was trained with (probe differs by {mismatch:.2g}): other weights or another version; "
                "pass the same --weights, or re-train the estimator"
            )


def resolve_device(device: str | None) -> str:
    """``device`` checked (:func:`physinfer.devices.check_device`); ``None``: ``"cuda"``
    when a GPU is visible, else ``"cpu"``."""
    checked = check_device(device)
    if checked is None:
        return "cuda" if torch.cuda.is_available() else "cpu"
    return checked


def _digest(tensors: Mapping[str, torch.Tensor], config_json: str) -> str:
    h = hashlib.sha256(config_json.encode())
    for name in sorted(tensors):
        t = tensors[name].detach().cpu().contiguous()
        h.update(f"{name}|{t.dtype}|{tuple(t.shape)}|".encode())
        h.update(t.numpy().tobytes() if t.dtype != torch.bfloat16 else t.float().numpy().tobytes())
    return "sha256:" + h.hexdigest()


def _space_difference(mine: ParameterSpace, theirs: ParameterSpace) -> str:
    extra, missing = set(mine.names) - set(theirs.names), set(theirs.names) - set(mine.names)
    parts = []
    if extra:
        parts.append(f"it infers {', '.join(sorted(extra))}, which this model lacks")
    if missing:
        parts.append(f"it lacks {', '.join(sorted(missing))}")
    for name in sorted(set(mine.names) & set(theirs.names)):
        if mine[name].to_dict() != theirs[name].to_dict():
            parts.append(
                f"{name}: its range {tuple(mine[name].bounds)}, here {tuple(theirs[name].bounds)}"
            )
    return "; ".join(parts) or "parameter order differs"
