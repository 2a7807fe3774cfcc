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

The distance alone is blind where the scale is large because the fit hardly moves: an
embedder that compares motion reads a nearly still clip as mostly sensor noise, so its camera
round trip is large and any video lies "near" it. An 8-s flag fed to the pendulum came back
"reproduces" (1.29 scales) from a 0.1-m pendulum swinging 1°, and a hanging cloth did too
(0.14). So the fit must also move about as much as the video: :func:`motion_energy`, read
on a coarse grid of the frames' luminance, may differ by at most :data:`MOTION_FACTOR`
either way. Measured (docs/real-footage.md): those two fits moved 0.12 and 0.11 times as much
as their videos; the real ball on a string's fit 0.46 (its bob is bigger in the frame than
the render's), the classroom film's 1.8; fits to clean simulated targets 0.35-1.34 (a
pendulum fitted at 60° for a 19° swing is framed wider, so it moves less in the frame). The
ratio reads looks and framing as well as motion, so the factor is loose: it catches a fit
that hardly moves, not one that moves a little differently (the pendulum's amortized
answer on the flag moved 0.27 times as much and passes).
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
#: The best fit's motion energy may be at most this factor below or above the target's.
MOTION_FACTOR = 4.0
#: Cells per side of the grid motion energy is read on: coarse enough that sensor noise
#: averages out and a subject's motion does not depend on its exact pixels.
MOTION_GRID = 16
#: Grey levels added to both energies before their ratio, so that two nearly still clips
#: (each within compression flicker of still) agree rather than divide noise by noise.
MOTION_FLOOR = 0.25
#: Frames read at a time for the motion energy.
MOTION_CHUNK = 64
METHOD = (
    f"best distance / max(noise floor, max over target and best fit of the distance to its own "
    f"H.264 CRF {CODEC_CRF} + noise round trip), at most {THRESHOLD:g}; and the best fit's motion energy "
    f"within a factor {MOTION_FACTOR:g} of the target's"
)


def motion_energy(frames: np.ndarray) -> float:
    """How much a clip moves: the RMS over a :data:`MOTION_GRID` grid of cell-mean luminance of
    each cell's deviation from its temporal mean, in grey levels. Independent of the clip's
    size, length and frame rate, so a target and a render of another size compare."""
    frames = np.asarray(frames)
    height, width = frames.shape[1:3]
    rows = np.linspace(0, height, min(MOTION_GRID, height) + 1).astype(int)
    cols = np.linspace(0, width, min(MOTION_GRID, width) + 1).astype(int)
    # A few dozen frames at a time: the 25-s phone clip as float32 at once took 4 GB and 14 s.
    sums = [_cell_sums(frames[start : start + MOTION_CHUNK], rows, cols) for start in range(0, len(frames), MOTION_CHUNK)]
    cells = np.concatenate(sums) / np.outer(np.diff(rows), np.diff(cols))[None]
    return float(np.sqrt(cells.var(axis=0).mean()))


def _cell_sums(frames: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """``(T, rows, cols)`` sums of luminance (the channels' mean) over the grid cells of ``frames``."""
    channels = frames.shape[3] if frames.ndim == 4 else 1
    # Channels and columns summed in one pass along each contiguous row (pixel-interleaved).
    flat = frames.reshape(*frames.shape[:2], -1)
    by_column = np.add.reduceat(flat, cols[:-1] * channels, axis=2, dtype=np.uint32)
    return np.add.reduceat(by_column, rows[:-1], axis=1).astype(np.float64) / channels


def motion_check(target: Clip, fit: Clip) -> dict[str, Any]:
    """``{ratio, target, fit, bounds, moves_alike}``: whether the fit moves about as much as the
    target (its energy within :data:`MOTION_FACTOR` of the target's, both raised by
    :data:`MOTION_FLOOR`)."""
    target_energy, fit_energy = motion_energy(target.frames), motion_energy(fit.frames)
    ratio = (fit_energy + MOTION_FLOOR) / (target_energy + MOTION_FLOOR)
    return {
        "ratio": round(ratio, 3),
        "target": round(target_energy, 3),
        "fit": round(fit_energy, 3),
        "bounds": [1 / MOTION_FACTOR, MOTION_FACTOR],
        "moves_alike": bool(1 / MOTION_FACTOR <= ratio <= MOTION_FACTOR),
    }


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


def fit_clip(pipeline: Pipeline, params: dict[str, float], target: Target, seed: int) -> Clip | None:
    """The best fit rendered as the target is seen; ``None`` when it cannot be re-simulated."""
    try:
        return pipeline.renderer.render(pipeline.simulator.simulate(params, seed=seed), target.render_params)
    except SimulationFailed:
        return None


def codec_distances(embedder: Any, target: Target, fit: Clip | None, seed: int) -> list[float]:
    """How far a camera moves an embedding: ``[at the target, at the best fit]`` (only the
    target's when there is no fit clip).

    Both are versions of "the same video"; the verdict takes the larger. The target alone is
    too strict: a real video already went through a camera, and a second pass moves it little
    (the 25-s ball on a string: 0.0016, while its best fit, 0.5 % from the true length, lies
    0.029 away and its render's round trip is 0.06).
    """
    distances = [round_trip_distance(embedder, target.clip, seed)]
    return distances if fit is None else [*distances, round_trip_distance(embedder, fit, seed)]


def verdict(
    best_distance: float, floor: float | None, codec: float | None, motion: dict[str, Any] | None = None
) -> dict[str, Any]:
    """The ``adequacy`` record: ``reproduces`` (the distance within :data:`THRESHOLD` scales
    and, where measured, the fit moving as the target does), ``statistic`` (distance in
    scales), ``threshold``, ``method``, the parts of the scale and ``motion``
    (:func:`motion_check`)."""
    scale = max(floor or 0.0, codec or 0.0)
    if not scale > 0 or not np.isfinite(best_distance):
        return {"reproduces": None, "statistic": None, "threshold": THRESHOLD, "method": METHOD,
                "floor": floor, "codec": codec, "note": "no scale of agreement could be measured"}  # fmt: skip
    statistic = best_distance / scale
    close = bool(statistic <= THRESHOLD)
    record = {
        "reproduces": close and (motion is None or motion["moves_alike"]),
        "statistic": round(float(statistic), 3),
        "threshold": THRESHOLD,
        "method": METHOD,
        "floor": floor,
        "codec": codec,
        "scale": scale,
    }
    return record if motion is None else {**record, "motion": motion}


def assess_fit(
    pipeline: Pipeline, params: dict[str, float], best_distance: float, target: Target,
    noise_floor: dict[str, Any] | None, seed: int,
) -> dict[str, Any]:  # fmt: skip
    """The verdict on a refinement's best fit (see the module docstring)."""
    floor = (noise_floor or {}).get("floor")
    floor = float(floor) if floor is not None and np.isfinite(floor) else None
    fit = fit_clip(pipeline, params, target, seed)
    codec = codec_distances(pipeline.embedder, target, fit, seed)
    motion = None if fit is None else motion_check(target.clip, fit)
    return {**verdict(best_distance, floor, max(codec), motion), "codec_distances": codec}


#: What the verdict advises when the model does not reproduce a video (``refine``, ``infer``).
ADVICE = "Run `physinfer diagnose` to find what the model lacks."
#: The same for ``diagnose``, whose chosen model already carries the best effect it found.
DIAGNOSE_ADVICE = (
    "No effect tried makes this video: it may show another phenomenon, another region of the frame "
    "(--roi), or more than the candidate effects can add."
)


def verdict_line(adequacy: dict[str, Any] | None, advice: str = ADVICE) -> str | None:
    """The printed sentence; ``None`` when the fit reproduces the target (or no verdict)."""
    if not adequacy or adequacy.get("reproduces") is not False:
        return None
    at = adequacy.get("at", "best fit")
    reasons = []
    if adequacy["statistic"] > adequacy["threshold"]:
        reasons.append(
            f"the {at} lies {adequacy['statistic']:.3g} times the scale of agreement from it "
            f"(reproducing needs ≤ {adequacy['threshold']:g})"
        )
    motion = adequacy.get("motion")
    if motion and not motion["moves_alike"]:
        low, high = motion["bounds"]
        reasons.append(
            f"the {at} moves {motion['ratio']:.2g} times as much as the video "
            f"(reproducing needs {low:.3g} to {high:.3g})"
        )
    return (
        f"THE MODEL DOES NOT REPRODUCE THIS VIDEO: {'; '.join(reasons)}; the numbers it gives are "
        f"unreliable. {advice}"
    )


def agreement_line(adequacy: dict[str, Any] | None) -> str | None:
    """The printed sentence when the fit (or the posterior's median) reproduces the target;
    ``None`` otherwise (:func:`verdict_line` speaks then)."""
    if not adequacy or not adequacy.get("reproduces"):
        return None
    motion = adequacy.get("motion")
    moves = f", moving {motion['ratio']:.2g} times as much" if motion else ""
    return (
        f"  the {adequacy.get('at', 'best fit')} reproduces the video ({adequacy['statistic']:.3g} times "
        f"the scale of agreement, ≤ {adequacy['threshold']:g}{moves})"
    )


def predictive_check(pipeline: Pipeline, params: dict[str, float], target: Target, seed: int) -> dict[str, Any]:
    """The verdict on an amortized posterior (``infer``): simulate its median twice (under two
    seeds: their distance is the noise floor of a stochastic phenomenon), and compare their
    distance to the target with the scale of agreement, and their motion with the target's, as
    :func:`assess_fit` does for a refinement's best fit. A video the model cannot make stays
    far from every θ, the posterior's median included."""
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
    return {**verdict(to_target, floor, codec, motion_check(target.clip, clips[0])), "at": "posterior median"}
