"""Render parameters ζ from the target: a linear read-out of the embedding, with its error.

A real target's camera is unknown, while ``refine`` renders every simulation at one ζ. Only
the ζ components that move the phenomenon's embedding need estimating
(``benchmarks/bench_zeta_sensitivity.py`` measures them; for the flag's SDN: the framing,
the camera azimuth and, less, its elevation; not the field of view, the light or the
background). The estimator is a ridge regression from the embedding ``s(x)`` to those
components, fitted on a generated dataset whose clips were rendered under random ζ (the
dataset engine stores ζ per clip, and ``posterior train`` caches the embeddings), with each
component's uncertainty the rms error on the dataset's held-out split. The embedding is
what ``refine``/``infer`` compute anyway, so an estimate costs one embedding.

The estimator file is an ``.npz`` (no pickles): ``names`` ``(K,)``, ``mean`` ``(E,)``,
``coef`` ``(K, E)``, ``intercept``/``sd``/``prior_sd`` ``(K,)``, ``bounds`` ``(K, 2)``, the
embedder's name and its fingerprint (``probe``, the embedding of
:func:`physinfer.posterior.fingerprint.probe_clip`): an estimator is refused for another
embedder or other weights.

Where a phenomenon's estimator is found: ``phenomenon.render_estimator`` (a path; the
proposed :class:`~physinfer.roles.Phenomenon` field), else :func:`register_render_estimator`,
else ``render_estimator_default.npz`` beside the phenomenon's shipped posterior.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.errors import UserInputError
from physinfer.io import atomic_save_npz
from physinfer.plugins import load_registry
from physinfer.posterior.fingerprint import PROBE_TOLERANCE, embedder_probe, probe_mismatch

FORMAT = "physinfer-render-estimator"
VERSION = 1
Z90 = 1.6448536269514722
"""Half-width of a normal 90 % interval in standard deviations."""

_REGISTRY: dict[str, Path] = {}


def register_render_estimator(phenomenon: str, path: str | Path) -> None:
    """Use the estimator file at ``path`` for ``phenomenon`` (by name)."""
    _REGISTRY[phenomenon] = Path(path)


def render_estimator_path(phenomenon: Any) -> Path | None:
    """The estimator file of ``phenomenon``, or ``None`` when it has none (module docstring)."""
    own = getattr(phenomenon, "render_estimator", None)
    if own:
        return Path(own)
    if phenomenon.name in _REGISTRY:
        return _REGISTRY[phenomenon.name]
    shipped = getattr(phenomenon, "default_posterior", None)
    if shipped:
        beside = Path(shipped).with_name("render_estimator_default.npz")
        if beside.is_file():
            return beside
    return None


@dataclass(frozen=True)
class RenderEstimator:
    """``ζ_k ≈ coef_k · (s − mean) + intercept_k``, clipped to ``bounds_k``.

    Attributes:
        names: ``(K,)`` ζ keys estimated.
        mean: ``(E,)`` mean training embedding.
        coef: ``(K, E)`` ridge coefficients.
        intercept: ``(K,)``.
        sd: ``(K,)`` rms error on held-out clips (the estimate's uncertainty).
        prior_sd: ``(K,)`` spread of ζ over the training clips (what a guess would miss by).
        bounds: ``(K, 2)`` range of ζ in the training clips; estimates are clipped to it.
        embedder: Name of the embedder it reads.
        probe: ``(E,)`` that embedder's fingerprint.
    """

    names: tuple[str, ...]
    mean: np.ndarray
    coef: np.ndarray
    intercept: np.ndarray
    sd: np.ndarray
    prior_sd: np.ndarray
    bounds: np.ndarray
    embedder: str
    probe: np.ndarray

    def predict(self, embedding: np.ndarray) -> np.ndarray:
        """``(K,)`` ζ estimates of one ``(E,)`` embedding, clipped to the training range."""
        x = np.asarray(embedding, dtype=np.float64)
        if x.shape != self.mean.shape or not np.isfinite(x).all():
            raise UserInputError(
                f"the embedding has shape {x.shape} (or non-finite values); the render estimator reads "
                f"{self.mean.shape[0]} finite values from {self.embedder!r}"
            )
        raw = self.coef @ (x - self.mean) + self.intercept
        return np.clip(raw, self.bounds[:, 0], self.bounds[:, 1])

    def estimate(self, embedding: np.ndarray) -> dict[str, Any]:
        """The JSON-friendly estimate: ``values``, ``sd``, ``ci90`` per name, and how much
        of the training spread it explains (``explained`` = 1 − sd² / prior_sd²)."""
        values = self.predict(embedding)
        out: dict[str, Any] = {"values": {}, "sd": {}, "ci90": {}, "explained": {}}
        for k, name in enumerate(self.names):
            lo, hi = self.bounds[k]
            half = Z90 * self.sd[k]
            out["values"][name] = round(float(values[k]), 4)
            out["sd"][name] = round(float(self.sd[k]), 4)
            out["ci90"][name] = [
                round(float(max(lo, values[k] - half)), 4),
                round(float(min(hi, values[k] + half)), 4),
            ]
            out["explained"][name] = round(float(1.0 - (self.sd[k] / self.prior_sd[k]) ** 2), 3)
        out["method"] = f"ridge regression on the {self.embedder} embedding"
        return out

    def save(self, path: str | Path) -> Path:
        """Write the ``.npz`` atomically."""
        atomic_save_npz(
            path,
            format=np.array(FORMAT),
            version=np.array(VERSION),
            names=np.array(self.names),
            mean=self.mean,
            coef=self.coef,
            intercept=self.intercept,
            sd=self.sd,
            prior_sd=self.prior_sd,
            bounds=self.bounds,
            embedder=np.array(self.embedder),
            probe=self.probe,
        )
        return Path(path)

    @classmethod
    def load(cls, path: str | Path) -> RenderEstimator:
        """Read an estimator file; refuses a file of another format (never unpickles)."""
        try:
            with np.load(path, allow_pickle=False) as d:
                if str(d["format"]) != FORMAT or int(d["version"]) != VERSION:
                    raise KeyError("format")
                return cls(
                    names=tuple(str(n) for n in d["names"]),
                    mean=d["mean"],
                    coef=d["coef"],
                    intercept=d["intercept"],
                    sd=d["sd"],
                    prior_sd=d["prior_sd"],
                    bounds=d["bounds"],
                    embedder=str(d["embedder"]),
                    probe=d["probe"],
                )
        except (OSError, KeyError, ValueError) as exc:
            raise UserInputError(f"{path} is not a render-parameter estimator ({exc})") from None

    def check_embedder(self, embedder: Any) -> None:
        """Refuse an embedder whose fingerprint differs from the one it was fitted on."""
        mismatch = probe_mismatch(list(self.probe), embedder_probe(embedder))
        if mismatch > PROBE_TOLERANCE:
            raise UserInputError(
                f"the render estimator was fitted on another {self.embedder!r} embedder (fingerprint off by "
                f"{mismatch:.3g}); refit it for these weights (benchmarks/make_render_estimator.py)"
            )


def fit_render_estimator(
    x_train: np.ndarray,
    zeta_train: Mapping[str, np.ndarray],
    x_test: np.ndarray,
    zeta_test: Mapping[str, np.ndarray],
    *,
    embedder: str,
    probe: np.ndarray,
    alphas: Sequence[float] = tuple(10.0 ** np.arange(-2, 4.5, 0.5)),
) -> RenderEstimator:
    """Fit one ridge regression per ζ component; its ``sd`` is the held-out rms error.

    The ridge strength is chosen per component by 5-fold cross-validation on the train split.

    Args:
        x_train: ``(N, E)`` embeddings of the training clips.
        zeta_train: ``{name: (N,)}`` their ζ values.
        x_test: ``(M, E)`` embeddings of held-out clips.
        zeta_test: ``{name: (M,)}``.
        embedder: The embedder's name.
        probe: ``(E,)`` its fingerprint.
        alphas: Ridge strengths tried.
    """
    names = tuple(zeta_train)
    mean = x_train.mean(axis=0)
    xc, xt = x_train - mean, x_test - mean
    coef, intercept, sd, prior_sd, bounds = [], [], [], [], []
    for name in names:
        y = np.asarray(zeta_train[name], dtype=np.float64)
        alpha = min(alphas, key=lambda a: _cv_error(xc, y, a))
        w, b = _ridge(xc, y, alpha)
        err = xt @ w + b - np.asarray(zeta_test[name], dtype=np.float64)
        coef.append(w)
        intercept.append(b)
        sd.append(math.sqrt(float(np.mean(err**2))))
        prior_sd.append(float(np.std(y)))
        bounds.append((float(y.min()), float(y.max())))
    return RenderEstimator(
        names=names,
        mean=mean,
        coef=np.array(coef),
        intercept=np.array(intercept),
        sd=np.array(sd),
        prior_sd=np.array(prior_sd),
        bounds=np.array(bounds),
        embedder=embedder,
        probe=np.asarray(probe, dtype=np.float64),
    )


def _ridge(x: np.ndarray, y: np.ndarray, alpha: float) -> tuple[np.ndarray, float]:
    """Ridge on centred ``x``: ``(E,)`` weights and the intercept."""
    b = float(y.mean())
    w = np.linalg.solve(x.T @ x + alpha * np.eye(x.shape[1]), x.T @ (y - b))
    return w, b


def _cv_error(x: np.ndarray, y: np.ndarray, alpha: float, folds: int = 5) -> float:
    idx = np.arange(len(y)) % folds
    err = 0.0
    for f in range(folds):
        w, b = _ridge(x[idx != f], y[idx != f], alpha)
        err += float(np.sum((x[idx == f] @ w + b - y[idx == f]) ** 2))
    return err


def estimate_render_params(
    phenomenon: Any, clip: Any, *, embedder: Any = None, device: str = "cpu"
) -> dict[str, Any]:
    """Estimate the ζ the embedding is sensitive to from a (prepared) target clip.

    Args:
        phenomenon: The :class:`~physinfer.roles.Phenomenon`.
        clip: The target :class:`~physinfer.types.Clip`, framed as the renderer frames
            (``physinfer prepare``'s output), at least as long as the embedder reads.
        embedder: The embedder to use (default: the phenomenon's default, built here).
        device: Torch device for an embedder built here.

    Returns:
        ``{"values": {name: value}, "sd": {...}, "ci90": {...}, "explained": {...},
        "method": str}`` (pass ``values`` to ``--render-set``; a user's ``--render-set``
        always overrides), or ``{"values": {}, "note": why}`` when the phenomenon has no
        estimator or the clip is too short.

    Raises:
        UserInputError: a damaged estimator file, or one fitted on other embedder weights.
    """
    path = render_estimator_path(phenomenon)
    if path is None:
        return {
            "values": {},
            "note": f"the plugin {phenomenon.name!r} has no render-parameter estimator",
        }
    estimator = RenderEstimator.load(path)
    if embedder is None:
        registry, _ = load_registry()
        embedder = registry.embedder(estimator.embedder, model=None, device=device)
    needed = int(embedder.n_frames) / float(embedder.fps)
    if clip.duration + 1e-6 < needed:
        return {
            "values": {},
            "note": f"the clip lasts {clip.duration:.2f} s; estimating ζ needs {needed:.2f} s",
        }
    estimator.check_embedder(embedder)
    result = estimator.estimate(np.asarray(embedder.embed(clip), dtype=np.float64))
    result["estimator"] = str(path)
    return result
