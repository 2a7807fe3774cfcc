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
  :data:`NOISE_SIGMA` grey levels), read back and embedded again (:func:`camera_scale`). It is
  measured on the target (also at the best fit's frame size, when the video is larger: noise
  averaged away in a large frame shows in a small one) and on the best fit's clip. A clean
  render's first pass through a camera moves it more than a second pass moves a video that has
  been through one, so the fit's own round trip may widen the scale, but by at most
  :data:`FIT_TRIP_FACTOR` times the target's: a fit whose picture a camera scatters tens of
  times more than the video's is not a picture of that video, yet it would place any video
  "near" itself (a pendulum held at 2.5 m with air drag "reproduced" a 0.7-m swing so, its
  round trip 43 times the target's).

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
from physinfer.evaluation import noise_seeds
from physinfer.types import Clip
from physinfer.video import center_crop_resize, grid_luminance

if TYPE_CHECKING:
    from physinfer.evaluation import Pipeline
    from physinfer.roles import Target

#: H.264 quality of the camera round trip (libx264's CRF: 23 default, phones about 23-28).
CODEC_CRF = 28
#: Sensor noise added before encoding, in grey levels (of 255).
NOISE_SIGMA = 2.0
#: Largest distance, in scales, at which the best fit counts as reproducing the target.
THRESHOLD = 10.0
#: The most the best fit's camera round trip may widen the scale, as a multiple of the target's
#: (docs/real-footage.md, 2026-11-27): fits to clean simulated pendulum targets 0.1-3.5 times,
#: the real ball on a string's fit 8.8 (at the fit's frame size), wrong fits that "reproduced"
#: a 0.7-m swing (held at 2.5 or 3 m, with air drag) 41-122.
FIT_TRIP_FACTOR = 4.0
#: The best fit's motion energy may be at most this factor below or above the target's.
MOTION_FACTOR = 4.0
#: Cells per side of the grid motion energy is read on: coarse enough that sensor noise
#: averages out and a subject's motion does not depend on its exact pixels.
MOTION_GRID = 16
#: Grey levels added to both energies before their ratio, so that two nearly still clips
#: (each within compression flicker of still) agree rather than divide noise by noise.
MOTION_FLOOR = 0.25
METHOD = (
    f"best distance / max(noise floor, camera scale), at most {THRESHOLD:g}, where the camera scale is "
    f"the target's distance to its own H.264 CRF {CODEC_CRF} + noise round trip, widened to the best "
    f"fit's by at most {FIT_TRIP_FACTOR:g} times; and the best fit's motion energy within a factor "
    f"{MOTION_FACTOR:g} of the target's"
)


def motion_energy(frames: np.ndarray) -> float:
    """How much a clip moves: the RMS over a :data:`MOTION_GRID` grid of cell-mean luminance of
    each cell's deviation from its temporal mean, in grey levels. Independent of the clip's
    size, length and frame rate, so a target and a render of another size compare."""
    return float(np.sqrt(grid_luminance(frames, MOTION_GRID).var(axis=0).mean()))


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


def at_fit_size(target: Clip, fit: Clip) -> Clip | None:
    """``target`` shrunk to about the fit's pixel count, its aspect kept; ``None`` unless the
    target has more pixels than the fit."""
    (height, width), (fit_h, fit_w) = target.frames.shape[1:3], fit.frames.shape[1:3]
    factor = float(np.sqrt(fit_h * fit_w / (height * width)))
    if factor >= 1.0:
        return None
    size = (max(1, round(height * factor)), max(1, round(width * factor)))
    return Clip(center_crop_resize(target.frames, size), target.fps)


def camera_scale(embedder: Any, target: Clip, fit: Clip | None, seed: int) -> dict[str, Any]:
    """How far a camera moves an embedding, and the verdict's ``scale`` made of it.

    ``target``: the target's round trip; ``target_at_fit_size``: the same at the fit's frame
    size (``None`` when the target is no larger); ``fit``: the best fit clip's (``None``
    without one); ``scale``: the larger target figure, widened to the fit's by at most
    :data:`FIT_TRIP_FACTOR` times (the module docstring says why); ``fit_capped``: whether
    the fit's was cut. The target alone is too strict: a real video already went through a
    camera, and a second pass moves it little (the 25-s ball on a string: 0.0016, at the fit's
    size 0.0048, while its best fit, 0.5 % from the true length, lies 0.027 away and its
    render's round trip is 0.043).
    """
    own = round_trip_distance(embedder, target, seed)
    smaller = None if fit is None else at_fit_size(target, fit)
    shrunk = None if smaller is None else round_trip_distance(embedder, smaller, seed)
    fit_trip = None if fit is None else round_trip_distance(embedder, fit, seed)
    floor = max(own, shrunk or 0.0)
    cap = FIT_TRIP_FACTOR * floor
    scale = floor if fit_trip is None else max(floor, min(fit_trip, cap))
    return {"target": own, "target_at_fit_size": shrunk, "fit": fit_trip, "scale": scale,
            "fit_capped": fit_trip is not None and fit_trip > cap}  # fmt: skip


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
    trips = camera_scale(pipeline.embedder, target.clip, fit, seed)
    motion = None if fit is None else motion_check(target.clip, fit)
    # ``codec_distances`` (the two round trips as measured) also serve the refined posterior.
    codec = [trips["target"]] if fit is None else [trips["target"], trips["fit"]]
    record = {**verdict(best_distance, floor, trips["scale"], motion), "codec_distances": codec, "camera": trips}
    return with_still_hint(record, target)


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
        trips = adequacy.get("camera") or {}
        if trips.get("fit_capped"):
            unstable = trips["fit"] / max(trips["target"], trips["target_at_fit_size"] or 0.0)
            reasons.append(
                f"a camera moves the clip of the {at} {unstable:.3g} times as much as the video "
                f"(its picture is unstable where the video's is not; counted up to {FIT_TRIP_FACTOR:g})"
            )
    motion = adequacy.get("motion")
    if motion and not motion["moves_alike"]:
        low, high = motion["bounds"]
        reasons.append(
            f"the {at} moves {motion['ratio']:.2g} times as much as the video "
            f"(reproducing needs {low:.3g} to {high:.3g})"
        )
    still = f" First: {adequacy['still_hint']}." if adequacy.get("still_hint") else ""
    return (
        f"THE MODEL DOES NOT REPRODUCE THIS VIDEO: {'; '.join(reasons)}; the numbers it gives are "
        f"unreliable.{still} {advice}"
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
    trips = camera_scale(embedder, target.clip, clips[0], seed)
    record = verdict(to_target, floor, trips["scale"], motion_check(target.clip, clips[0]))
    return with_still_hint({**record, "camera": trips, "at": "posterior median"}, target)


def with_still_hint(record: dict[str, Any], target: Target) -> dict[str, Any]:
    """``record`` with the conditioning's note on a still opening or ending of the video
    (``hint``; :func:`physinfer.conditioning.note_still_ends`), which a failing verdict repeats."""
    still = (target.conditions or {}).get("still")
    return record if not still else {**record, "still_hint": still["hint"]}
