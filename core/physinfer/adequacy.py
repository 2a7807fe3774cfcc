"""Does the best fit reproduce the target? The model-adequacy verdict of every answer.

A refinement always ends with a best θ, whether or not the model can make the video at all
(a real pendulum fed to a world whose pivot is always in view; a two-corner flag read as a
hoist-pinned one). A number then means nothing, and the tool must say so. The verdict
compares the best fit's distance to the target with the scale on which the tool itself sees
two versions of one video differ:

- ``floor``: the noise floor, the median distance between re-simulations of the best θ under
  other seeds (0 for a deterministic phenomenon);
- ``codec``: the distance between a clip and that clip passed through what a camera does to
  a video (H.264 at a phone's quality, :data:`CODEC_CRF`, and sensor noise of
  :data:`NOISE_SIGMA` grey levels), read back and embedded again; measured on the target and
  on the best fit's clip, the larger taken.

The scale is the larger of the two; the best fit reproduces the target when its distance is
at most :data:`THRESHOLD` scales. The threshold's false-alarm rate on clean simulated
targets (written to mp4, refined with defaults) is measured by ``benchmarks/bench_adequacy.py``
(docs/benchmarks.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.as_given import camera
from physinfer.errors import SimulationFailed
from physinfer.noise import noise_seeds
from physinfer.types import Clip

if TYPE_CHECKING:
    from physinfer.evaluation import Pipeline
    from physinfer.roles import Target

#: H.264 quality of the camera round trip (libx264's CRF: 23 default, phones about 23-28).
CODEC_CRF = 28
#: Sensor noise added before encoding, in grey levels (of 255).
NOISE_SIGMA = 2.0
#: Largest distance, in scales, at which the best fit counts as reproducing the target.
THRESHOLD = 10.0
METHOD = (
    f"best distance / max(noise floor, max over target and best fit of the distance to its own "
    f"H.264 CRF {CODEC_CRF} + noise round trip)"
)


def camera_round_trip(clip: Clip, *, crf: int = CODEC_CRF, sigma: float = NOISE_SIGMA, seed: int = 0) -> Clip:
    """``clip`` with sensor noise, written as H.264 at ``crf`` and read back
    (:func:`physinfer.as_given.camera` without white balance or blur)."""
    effects = {"crf": crf, "noise": sigma, "gain": np.ones(3), "blur": 0.0}
    return camera(clip, effects, np.random.default_rng(seed))


def round_trip_distance(embedder: Any, clip: Clip, seed: int) -> float:
    """Squared distance between ``clip``'s embedding and its camera round trip's."""
    clean = np.asarray(embedder.embed(clip), float)
    degraded = np.asarray(embedder.embed(camera_round_trip(clip, seed=seed)), float)
    return float(np.sum((clean - degraded) ** 2))


def codec_distances(pipeline: Pipeline, params: dict[str, float], target: Target, seed: int) -> list[float]:
    """How far a camera moves an embedding: ``[at the target, at the best fit]`` (only the
    target's when the best fit cannot be re-simulated).

    Both are versions of "the same video"; the verdict takes the larger. The target alone is
    too strict: a real video already went through a camera, and a second pass moves it little
    (the 25-s ball on a string: 0.0016, while its best fit, 0.5 % from the true length, lies
    0.029 away and its render's round trip is 0.06).
    """
    distances = [round_trip_distance(pipeline.embedder, target.clip, seed)]
    try:
        clip = pipeline.renderer.render(pipeline.simulator.simulate(params, seed=seed), target.render_params)
    except SimulationFailed:
        return distances
    return [*distances, round_trip_distance(pipeline.embedder, clip, seed)]


def verdict(best_distance: float, floor: float | None, codec: float | None) -> dict[str, Any]:
    """The ``adequacy`` record: ``reproduces``, ``statistic`` (distance in scales),
    ``threshold``, ``method``, and the parts of the scale."""
    scale = max(floor or 0.0, codec or 0.0)
    if not scale > 0 or not np.isfinite(best_distance):
        return {"reproduces": None, "statistic": None, "threshold": THRESHOLD, "method": METHOD,
                "floor": floor, "codec": codec, "note": "no scale of agreement could be measured"}  # fmt: skip
    statistic = best_distance / scale
    return {
        "reproduces": bool(statistic <= THRESHOLD),
        "statistic": round(float(statistic), 3),
        "threshold": THRESHOLD,
        "method": METHOD,
        "floor": floor,
        "codec": codec,
        "scale": scale,
    }


def assess_fit(
    pipeline: Pipeline, params: dict[str, float], best_distance: float, target: Target,
    noise_floor: dict[str, Any] | None, seed: int,
) -> dict[str, Any]:  # fmt: skip
    """The verdict on a refinement's best fit (see the module docstring)."""
    floor = (noise_floor or {}).get("floor")
    floor = float(floor) if floor is not None and np.isfinite(floor) else None
    codec = codec_distances(pipeline, params, target, seed)
    return {**verdict(best_distance, floor, max(codec)), "codec_distances": codec}


def verdict_line(adequacy: dict[str, Any] | None) -> str | None:
    """The printed sentence; ``None`` when the fit reproduces the target (or no verdict)."""
    if not adequacy or adequacy.get("reproduces") is not False:
        return None
    return (
        f"THE MODEL DOES NOT REPRODUCE THIS VIDEO: the {adequacy.get('at', 'best fit')} lies "
        f"{adequacy['statistic']:.3g} times "
        f"the scale of agreement from it (reproducing needs ≤ {adequacy['threshold']:g}); the numbers "
        "it gives are unreliable. Run `physinfer diagnose` to find what the model lacks."
    )


def agreement_line(adequacy: dict[str, Any] | None) -> str | None:
    """The printed sentence when the fit (or the posterior's median) reproduces the target;
    ``None`` otherwise (:func:`verdict_line` speaks then)."""
    if not adequacy or not adequacy.get("reproduces"):
        return None
    return (
        f"  the {adequacy.get('at', 'best fit')} reproduces the video ({adequacy['statistic']:.3g} times "
        f"the scale of agreement, ≤ {adequacy['threshold']:g})"
    )


def predictive_check(pipeline: Pipeline, params: dict[str, float], target: Target, seed: int) -> dict[str, Any]:
    """The verdict on an amortized posterior (``infer``): simulate its median twice (under two
    seeds: their distance is the noise floor of a stochastic phenomenon), and compare their
    distance to the target with the scale of agreement, as :func:`assess_fit` does for a
    refinement's best fit. A video the model cannot make stays far from every θ, the
    posterior's median included."""
    try:
        clips = [
            pipeline.renderer.render(pipeline.simulator.simulate(params, seed=s), target.render_params)
            for s in noise_seeds(seed, 2)
        ]
    except SimulationFailed as exc:
        return {"reproduces": None, "statistic": None, "threshold": THRESHOLD, "method": METHOD,
                "note": f"the posterior median could not be simulated: {exc}"}  # fmt: skip
    embedder = pipeline.embedder
    target_embedding = np.asarray(embedder.embed(target.clip), float)
    embeddings = [np.asarray(embedder.embed(clip), float) for clip in clips]
    to_target = float(np.median([np.sum((e - target_embedding) ** 2) for e in embeddings]))
    floor = float(np.sum((embeddings[0] - embeddings[1]) ** 2))
    codec = max(round_trip_distance(embedder, clips[0], seed), round_trip_distance(embedder, target.clip, seed))
    return {**verdict(to_target, floor, codec), "at": "posterior median"}
