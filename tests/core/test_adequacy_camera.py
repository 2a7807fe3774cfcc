"""The verdict's camera scale: the best fit's own round trip widens it, but only so far.

A pendulum held at 2.5 m with air drag "reproduced" a 0.7-m swing: the camera scattered the
fit's picture 43 times as much as the video's, and the scale took the fit's.
"""

import numpy as np

from physinfer.adequacy import FIT_TRIP_FACTOR, at_fit_size, camera_scale, verdict, verdict_line
from physinfer.types import Clip


class PixelEmbedder:
    """Embeds a clip as its pixels (every 4th): what H.264 does to them, it does to the embedding."""

    def embed(self, clip: Clip) -> np.ndarray:
        return clip.frames[:, ::4, ::4].astype(float).ravel() / 255.0


def gradient(size: int = 64, frames: int = 12) -> Clip:
    """A smooth picture drifting slowly: a camera barely moves it."""
    x = np.linspace(0, 200, size)
    return Clip(np.stack([np.broadcast_to((x[None, :, None] + t) % 256, (size, size, 3)) for t in range(frames)]).astype(np.uint8), 25.0)


def checkerboard(size: int = 64, frames: int = 12) -> Clip:
    """One-pixel black-and-white squares, flipping each frame: H.264 at a phone's quality smears them."""
    board = (np.indices((size, size)).sum(axis=0) % 2 * 255).astype(np.uint8)
    return Clip(np.stack([np.repeat((board if t % 2 else 255 - board)[..., None], 3, axis=2) for t in range(frames)]), 25.0)


def test_a_fit_the_camera_scatters_widens_the_scale_only_so_far():
    embedder = PixelEmbedder()
    stable = camera_scale(embedder, gradient(), gradient(), seed=0)
    assert not stable["fit_capped"] and stable["scale"] == max(stable["target"], stable["fit"])
    fragile = camera_scale(embedder, gradient(), checkerboard(), seed=0)
    assert fragile["fit"] > 10 * FIT_TRIP_FACTOR * fragile["target"]  # the board is unstable, the video is not
    assert fragile["fit_capped"] and np.isclose(fragile["scale"], FIT_TRIP_FACTOR * fragile["target"])
    assert fragile["target_at_fit_size"] is None  # the same frame size


def test_a_video_larger_than_the_fit_is_also_measured_at_the_fit_s_size():
    big, small = gradient(size=128), gradient(size=64)
    shrunk = at_fit_size(big, small)
    assert shrunk is not None and shrunk.frames.shape == small.frames.shape
    assert at_fit_size(small, big) is None and at_fit_size(small, small) is None
    trips = camera_scale(PixelEmbedder(), big, small, seed=0)
    assert trips["target_at_fit_size"] is not None
    assert trips["scale"] >= max(trips["target"], trips["target_at_fit_size"])


def test_the_line_says_the_fit_is_unstable_to_a_camera():
    trips = {"target": 0.2, "target_at_fit_size": None, "fit": 9.0, "scale": 0.8, "fit_capped": True}
    record = {**verdict(60.0, 0.0, trips["scale"]), "camera": trips}
    line = verdict_line(record)
    assert record["reproduces"] is False and "75 times the scale of agreement" in line
    assert "a camera moves the clip of the best fit 45 times as much as the video" in line
    assert "a camera moves" not in verdict_line(verdict(60.0, 0.0, 0.8))
