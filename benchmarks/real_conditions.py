"""Degradations of ``bench_real_conditions.py``: what a phone does to a flag video.

Photo-like backgrounds made procedurally here (a sky with soft clouds over a tree line with
leaf texture; unlike the renderer's own backgrounds, never seen in training), flag renders
with an alpha channel composited small and off-centre into wide frames, camera shake, a
white-balance and gamma shift, sensor noise and H.264 at a chosen CRF. numpy, Pillow, PyAV.
"""

from __future__ import annotations

import tempfile
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from physinfer.types import Trajectory


def _noise_field(
    rng: np.random.Generator, height: int, width: int, scales: tuple[int, ...]
) -> np.ndarray:
    """``(H, W)`` smooth noise in [0, 1]: white noise at several scales, bicubically enlarged."""
    field = np.zeros((height, width), np.float32)
    for scale in scales:
        small = rng.normal(size=(height // scale + 2, width // scale + 2)).astype(np.float32)
        field += scale**0.5 * np.asarray(
            Image.fromarray(small).resize((width, height), Image.Resampling.BICUBIC)
        )
    return (field - field.min()) / max(float(np.ptp(field)), 1e-6)


def photo_background(height: int, width: int, seed: int) -> np.ndarray:
    """``(H, W, 3)`` uint8: a blue sky with clouds above a ragged line of textured trees."""
    rng = np.random.default_rng(seed)
    rows = np.linspace(0.0, 1.0, height, dtype=np.float32)[:, None, None]
    top, horizon = np.array([70, 120, 200], np.float32), np.array([190, 210, 230], np.float32)
    sky = top + (horizon - top) * rows**0.8
    clouds = np.clip((_noise_field(rng, height, width, (4, 16, 64)) - 0.45) * 3.0, 0.0, 1.0)[
        ..., None
    ]
    image = sky * (1 - clouds) + np.array([235, 235, 238], np.float32) * clouds
    # Tree line: crowns as a smooth ridge across the lower part, leaves as fine noise.
    ridge = 0.55 + 0.2 * _noise_field(rng, 1, width, (8, 32, 128))[0]
    crowns = rows[..., 0] > ridge[None, :]
    leaves = _noise_field(rng, height, width, (1, 3, 9))[..., None]
    green = np.array([40, 75, 35], np.float32) + np.array([60, 80, 40], np.float32) * leaves
    image = np.where(crowns[..., None], green, image)
    return np.clip(image, 0, 255).astype(np.uint8)


def render_rgba(renderer: Any, trajectory: Trajectory, zeta: dict[str, Any]) -> np.ndarray:
    """``(T, H, W, 4)`` premultiplied RGBA renders of the flag and pole (no background).

    Uses the flag renderer's scene building; only the compositing is left out.
    """
    from physinfer_flag.flag_scene import measure_flag
    from physinfer_flag.render_params import FlagRenderParams
    from physinfer_flag.sheet_render import DoubleSidedSheet

    params = FlagRenderParams.from_mapping(zeta)
    height, width = params.size
    sheet = DoubleSidedSheet(trajectory.faces, trajectory.vertices.shape[1])
    scene, flag = renderer._build_scene(trajectory, measure_flag(trajectory), sheet, params)
    context = renderer._context_for(width, height)
    out = np.empty((trajectory.n_frames, height, width, 4), np.uint8)
    for i, positions in enumerate(trajectory.vertices):
        context.update_vertices(flag, *sheet.buffers(positions))
        out[i] = context.render(scene, rgba=True)
    return out


def composite(
    rgba: np.ndarray, background: np.ndarray, xy: tuple[int, int], shifts: np.ndarray | None = None
) -> np.ndarray:
    """``(T, H, W, 3)``: ``rgba`` frames put at ``xy`` on ``background`` (``(H + 2m, W + 2m, 3)``
    with a margin ``m`` for the shake), the view moved by ``shifts`` ``(T, 2)`` whole pixels."""
    from physinfer_flag.sheet_render import composite_over

    n, side = rgba.shape[0], rgba.shape[1]
    margin = 8
    height, width = background.shape[0] - 2 * margin, background.shape[1] - 2 * margin
    shifts = np.zeros((n, 2), int) if shifts is None else np.asarray(shifts, int)
    x, y = xy
    frames = np.empty((n, height, width, 3), np.uint8)
    for t in range(n):
        canvas = background.copy()
        window = canvas[margin + y : margin + y + side, margin + x : margin + x + side]
        canvas[margin + y : margin + y + side, margin + x : margin + x + side] = composite_over(
            rgba[t], window
        )
        left, top = margin - shifts[t][0], margin - shifts[t][1]
        frames[t] = canvas[top : top + height, left : left + width]
    return frames


def shake(n: int, rng: np.random.Generator, amplitude: int = 3) -> np.ndarray:
    """``(T, 2)`` hand shake in whole pixels: a smoothed random walk within ±``amplitude``."""
    walk = np.cumsum(rng.normal(0, 1.0, (n, 2)), axis=0)
    walk -= walk.mean(axis=0)
    return np.clip(
        np.round(walk * amplitude / max(np.abs(walk).max(), 1e-6)), -amplitude, amplitude
    ).astype(int)


def white_balance(
    frames: np.ndarray, gains: tuple[float, float, float] = (1.15, 1.0, 0.8), gamma: float = 0.85
) -> np.ndarray:
    """A warm white balance (per-channel gains) and a brighter tone curve."""
    f = (frames.astype(np.float32) / 255.0) ** gamma * np.asarray(gains, np.float32)
    return np.clip(f * 255.0 + 0.5, 0, 255).astype(np.uint8)


def sensor_noise(frames: np.ndarray, rng: np.random.Generator, sigma: float = 6.0) -> np.ndarray:
    """Gaussian read noise (``sigma`` gray levels) plus shot noise growing with brightness."""
    f = frames.astype(np.float32)
    noisy = f + rng.normal(0.0, 1.0, f.shape).astype(np.float32) * np.sqrt(sigma**2 + 0.05 * f)
    return np.clip(noisy + 0.5, 0, 255).astype(np.uint8)


def h264(frames: np.ndarray, fps: float, crf: int = 35) -> np.ndarray:
    """Encode with libx264 at ``crf`` (yuv420p, as phones do) and decode again."""
    import av

    from physinfer.video import read_video

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "clip.mp4"
        with av.open(str(path), mode="w", format="mp4") as container:
            stream = container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1001))
            stream.width, stream.height = frames.shape[2], frames.shape[1]
            stream.pix_fmt = "yuv420p"
            stream.options = {"crf": str(crf), "preset": "veryfast"}
            for frame in frames:
                for packet in stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")):
                    container.mux(packet)
            for packet in stream.encode():
                container.mux(packet)
        return read_video(path).frames
