"""Clips as users give them: what a camera and a file do to a rendered clip, and the path a
user's video takes before it is embedded.

An estimator trained on clips straight from the renderer meets, at inference, a video that
went through a camera (white balance, blur, sensor noise), an H.264 encoder, a decoder and
:func:`physinfer.conditioning.condition_target`. Where the renders are exactly still (a
plain wall), an embedding has dimensions that never vary in training and carry codec noise
in every target: a spring estimator trained on such clips put the whole posterior on a bound
for every mp4 target while its calibration on the training format said "calibrated" (issue
44). :func:`as_given` sends a training or held-out clip down the user's path instead, with
camera effects drawn per clip from :class:`CameraModel`, so the estimator learns and is
checked on what it will be given.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from physinfer import video
from physinfer.conditioning import Conditioning, condition_target
from physinfer.errors import UserInputError
from physinfer.types import Clip


@dataclass(frozen=True)
class CameraModel:
    """Ranges the camera effects of one clip are drawn from (uniformly, per clip).

    Attributes:
        crf: libx264's quality range (18 near-transparent, 23 its default, phones 23–28,
            35 a heavily compressed upload).
        noise: Sensor noise, standard deviation in grey levels (of 255).
        gain: Per-channel white-balance gain (each of R, G, B drawn independently).
        blur_share: Share of clips blurred (focus, motion) …
        blur: … with a Gaussian of this standard deviation in pixels.
    """

    crf: tuple[int, int] = (18, 35)
    noise: tuple[float, float] = (0.0, 3.0)
    gain: tuple[float, float] = (0.85, 1.15)
    blur_share: float = 0.3
    blur: tuple[float, float] = (0.3, 1.0)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready ranges (an estimator's configuration records them)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CameraModel:
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})

    def draw(self, rng: np.random.Generator) -> dict[str, Any]:
        """The effects of one clip: ``{crf, noise, gain (3,), blur}`` (blur 0: none)."""
        blurred = rng.uniform() < self.blur_share
        return {
            "crf": int(rng.integers(self.crf[0], self.crf[1] + 1)),
            "noise": float(rng.uniform(*self.noise)),
            "gain": rng.uniform(*self.gain, size=3),
            "blur": float(rng.uniform(*self.blur)) if blurred else 0.0,
        }


#: Frames sent through the camera effects at a time: the float copies of a whole phone clip
#: (1,535 frames of 550 × 310, colour) took 3 GB, its noise draw 6 GB more.
CHUNK_FRAMES = 32


def camera(clip: Clip, effects: dict[str, Any], rng: np.random.Generator) -> Clip:
    """``clip`` through a camera and a file: white balance, blur and sensor noise, then an
    H.264 encoding at ``effects["crf"]`` read back. A grayscale clip is seen as colour."""
    pixels = filmed_pixels(np.asarray(clip.frames), effects, rng)
    return video.round_trip(Clip(pixels, clip.fps), crf=effects["crf"])


def filmed_pixels(frames: np.ndarray, effects: dict[str, Any], rng: np.random.Generator) -> np.ndarray:
    """``(T, H, W, 3)`` uint8: white balance, blur and sensor noise applied to ``frames``
    (``(T, H, W[, C])``, grey or colour), :data:`CHUNK_FRAMES` frames at a time. Every effect
    acts within a frame and the noise is drawn in frame order, so the pixels are those of the
    whole clip at once."""
    if frames.ndim == 3:
        frames = frames[..., None]
    out = np.empty((*frames.shape[:3], 3), dtype=np.uint8)
    gain = np.asarray(effects["gain"], dtype=np.float32)
    for start in range(0, len(frames), CHUNK_FRAMES):
        chunk = frames[start : start + CHUNK_FRAMES].astype(np.float32)
        if chunk.shape[-1] == 1:
            chunk = np.repeat(chunk, 3, axis=-1)
        chunk = chunk * gain
        if effects["blur"] > 0:
            chunk = _gaussian_blur(chunk, effects["blur"])
        if effects["noise"] > 0:
            chunk = chunk + rng.normal(0.0, effects["noise"], chunk.shape).astype(np.float32)
        out[start : start + len(chunk)] = np.clip(np.rint(chunk), 0, 255)
    return out


def _gaussian_blur(frames: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur over the two image axes of ``(T, H, W, C)`` frames."""
    from scipy.ndimage import gaussian_filter

    return gaussian_filter(frames, sigma=(0.0, sigma, sigma, 0.0), mode="nearest", truncate=3.0)


def as_given(
    clip: Clip,
    *,
    phenomenon: Any,
    embedder: Any,
    model: CameraModel,
    rng: np.random.Generator,
) -> Clip:
    """``clip`` as ``infer`` would see it had a user filmed it: :func:`camera`, then the
    conditioning ``infer`` applies to a user's file (framing or the still-background freeze;
    no ζ estimate, as ``infer`` makes none). A clip the conditioning refuses (e.g. two things
    move) — as it would refuse such a target, whose posterior is then never asked for — is
    returned through the camera only.
    """
    filmed = camera(clip, model.draw(rng), rng)
    try:
        conditioned, _zeta, _record = condition_target(
            phenomenon, embedder, filmed, Conditioning(estimate_render=False, mirror=False), {}
        )
    except UserInputError:
        return filmed
    return conditioned
