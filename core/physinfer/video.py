"""Video input and output, generic for every plugin.

Reads mp4/avi/mov/mkv/webm (PyAV), gif (Pillow) and folders of images into a
:class:`~physinfer.types.Clip`; resamples to an embedder's frame rate, converts to
grayscale, centre-crops and resizes; writes mp4 (H.264) and gif. Every failure a user
can cause comes back as a :class:`~physinfer.errors.UserInputError` that says what to do.
"""

from __future__ import annotations

import logging
import math
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from physinfer.errors import UserInputError
from physinfer.io import atomic_path
from physinfer.moved import moved_names
from physinfer.types import FPS_RANGE, Clip, check_fps
from physinfer.zeroed_heap import zero_filled_allocations

VIDEO_SUFFIXES = {".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v"}
IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp"}


_log = logging.getLogger(__name__)

# A user's target read in bounded memory (read_target_video) moved to physinfer.target.
__getattr__ = moved_names(__name__)


def read_video(
    path: str | Path,
    fps: float | None = None,
    max_frames: int | None = None,
    *,
    max_side: int | None = None,
    skip_frames: int = 0,
) -> Clip:
    """Read a video file or a folder of images.

    Args:
        path: A video file, a gif, or a folder whose images (sorted by name) are frames.
        fps: Frame rate to assume; required for image folders and for files whose
            container does not say. Overrides the container's rate when given.
        max_frames: Stop after this many frames (None: all).
        max_side: Downscale frames whose longer side exceeds this while decoding (None: as
            stored).
        skip_frames: Frames decoded and dropped before the first one kept (a part of a long
            video is read without holding what comes before it).

    Returns:
        RGB clip, frames ``(T, H, W, 3)`` uint8.

    Raises:
        UserInputError: missing/unreadable file, no frames, unknown frame rate.
    """
    if fps is not None:  # given, so say it is wrong
        fps = check_fps(fps)
    path = Path(path)
    if not path.exists():
        raise UserInputError(f"video {path} does not exist; check the path")
    if path.is_dir():
        frames, found_fps = _read_image_folder(path, max_frames, max_side, skip_frames), None
    elif path.suffix.lower() == ".gif":
        frames, found_fps = _read_gif(path, max_frames, max_side, skip_frames)
    elif path.suffix.lower() in VIDEO_SUFFIXES:
        frames, found_fps = _read_pyav(path, max_frames, max_side, skip_frames)
    else:
        raise UserInputError(
            f"{path}: unsupported video format {path.suffix!r}; use one of "
            f"{', '.join(sorted(VIDEO_SUFFIXES | {'.gif'}))} or a folder of images"
        )
    if len(frames) == 0:
        after = f" after its first {skip_frames}" if skip_frames else ""
        raise UserInputError(f"{path}: the video has no frames{after}")
    rate = fps if fps is not None else found_fps
    if rate is None or not math.isfinite(rate) or rate <= 0:
        raise UserInputError(f"{path}: cannot tell the frame rate; pass it with --fps")
    return Clip(_to_rgb(np.stack(frames)), float(rate))


def _to_rgb(frames: np.ndarray) -> np.ndarray:
    if frames.ndim == 3:
        frames = frames[..., None]
    if frames.shape[3] == 1:
        frames = np.repeat(frames, 3, axis=3)
    elif frames.shape[3] == 4:
        frames = frames[..., :3]
    if frames.dtype != np.uint8:
        frames = np.clip(frames, 0, 255).astype(np.uint8)
    return np.ascontiguousarray(frames)


def scaled_size(width: int, height: int, max_side: int | None) -> tuple[int, int]:
    """``(width, height)`` shrunk (aspect kept, even numbers) so the longer side is at most
    ``max_side``; unchanged when it already is."""
    if max_side is None or max(width, height) <= max_side:
        return width, height
    scale = max_side / max(width, height)
    return max(2, int(round(width * scale / 2)) * 2), max(2, int(round(height * scale / 2)) * 2)


def upright(pixels: np.ndarray, matrix: tuple[int, int, int, int] | None) -> np.ndarray:
    """A decoded frame as it is meant to be seen: transformed by the file's display matrix
    (:func:`display_matrix`; ``None``: as stored). A phone stores a portrait video as landscape
    frames and a rotation; a front camera or an editor may store a mirror too. Read without
    it, a flag's gravity would point sideways; read as a rotation alone (PyAV's
    ``frame.rotation``), a mirrored video came out upside down (checked against ffmpeg's own
    autorotation for every rotation and flip: tests/core/test_video.py)."""
    if matrix is None:
        return pixels
    a, b, c, d = matrix
    if a * d - b * c < 0:  # a mirror: flip the stored picture, then turn it by the rest
        pixels, a, b = pixels[:, ::-1], -a, -b
    turns = int(round(math.degrees(math.atan2(c, a)) / 90.0)) % 4
    return np.ascontiguousarray(np.rot90(pixels, turns)) if turns or pixels.strides[1] < 0 else pixels


def display_matrix(frame: object) -> tuple[int, int, int, int] | None:
    """The 2 × 2 part of a decoded frame's display matrix (libavutil's, 16.16 fixed point,
    rounded to whole numbers: quarter turns and mirrors), or ``None`` for none. Falls back to
    PyAV's ``frame.rotation`` (a rotation alone) where the side data cannot be read."""
    try:
        for data in frame.side_data:  # type: ignore[attr-defined]
            if str(getattr(data, "type", "")).endswith("DISPLAYMATRIX"):
                entries = np.frombuffer(bytes(data), dtype=np.int32)[[0, 1, 3, 4]] / 65536.0
                return tuple(int(v) for v in np.round(entries))  # type: ignore[return-value]
        return None
    except Exception:  # an older PyAV without readable side data
        turns = int(round(float(getattr(frame, "rotation", 0) or 0) / 90.0)) % 4
        return [None, (0, -1, 1, 0), (-1, 0, 0, -1), (0, 1, -1, 0)][turns]


def _read_pyav(
    path: Path, max_frames: int | None, max_side: int | None = None, skip: int = 0
) -> tuple[list[np.ndarray], float | None]:
    import av

    try:
        with av.open(str(path)) as container:
            if not container.streams.video:
                raise UserInputError(f"{path}: the file has no video stream")
            stream = container.streams.video[0]
            rate = stream.average_rate or stream.guessed_rate or stream.base_rate
            frames = []
            times: list[float | None] = []
            for index, frame in enumerate(container.decode(stream)):
                if index < skip:
                    continue
                width, height = scaled_size(frame.width, frame.height, max_side)
                frames.append(upright(frame.to_ndarray(width=width, height=height, format="rgb24"), display_matrix(frame)))
                times.append(float(frame.pts * frame.time_base) if frame.pts is not None and frame.time_base else None)
                if max_frames is not None and len(frames) >= max_frames:
                    break
            tick = float(stream.time_base) if stream.time_base else 0.0
    except UserInputError:
        raise
    except Exception as exc:  # av raises many types for corrupt input
        raise UserInputError(f"{path}: cannot decode the video ({type(exc).__name__}: {exc})") from None
    uniform = _uniform_times(path, frames, times, tick, max_frames)
    if uniform is not None:
        return uniform
    return frames, float(rate) if rate else None


#: Frame intervals that differ from their median by more than this fraction (beyond the
#: container's time-base rounding) make a video variable-frame-rate.
VFR_TOLERANCE = 0.10


def _uniform_times(
    path: Path, frames: list[np.ndarray], times: Sequence[float | None], tick: float, max_frames: int | None
) -> tuple[list[np.ndarray], float] | None:
    """A variable-frame-rate video's frames resampled at uniform times, or None for a
    constant-rate one (or one without timestamps).

    A phone's video often drops or stretches frames; read at its average rate, its motion
    would run at an uneven speed and every duration measured on it would be off. The frame
    times ``pts × time_base`` are checked: intervals that stray from their median by more
    than :data:`VFR_TOLERANCE` (plus one time-base tick of rounding) mark the video as
    variable-rate, and it is resampled at the median interval's rate by taking, at each
    uniform time, the frame whose timestamp is nearest (a warning says so).
    """
    if len(frames) < 3 or any(t is None for t in times):
        return None
    t = np.asarray(times, dtype=np.float64)
    dt = np.diff(t)
    if not np.all(np.isfinite(dt)) or np.any(dt <= 0):
        return None  # out-of-order or repeated timestamps: keep the container's rate
    step = float(np.median(dt))
    if np.max(np.abs(dt - step)) <= VFR_TOLERANCE * step + tick:
        return None
    fps = 1.0 / step
    n_out = int(np.floor((t[-1] - t[0]) * fps + 1e-9)) + 1
    if max_frames is not None:
        n_out = min(n_out, max_frames)
    uniform = t[0] + np.arange(n_out) / fps
    right = np.clip(np.searchsorted(t, uniform), 1, len(t) - 1)
    idx = np.where(uniform - t[right - 1] <= t[right] - uniform, right - 1, right)
    _log.warning(
        "warning: %s has a variable frame rate (frame intervals %.1f-%.1f ms); resampled to %.3g fps at uniform "
        "times (nearest frame), %d frames from %d",
        path, 1e3 * dt.min(), 1e3 * dt.max(), fps, n_out, len(frames),
    )  # fmt: skip
    return [frames[i] for i in idx], fps


def _pil_rgb(image: object, max_side: int | None) -> np.ndarray:
    """A Pillow image as RGB, downscaled to ``max_side``."""
    from PIL import Image

    rgb = image.convert("RGB")  # type: ignore[attr-defined]
    size = scaled_size(rgb.width, rgb.height, max_side)
    return np.asarray(rgb if size == rgb.size else rgb.resize(size, Image.Resampling.BILINEAR))


def _read_gif(
    path: Path, max_frames: int | None, max_side: int | None = None, skip: int = 0
) -> tuple[list[np.ndarray], float | None]:
    from PIL import Image, ImageSequence

    try:
        with Image.open(path) as im:
            frames, durations = [], []
            for frame in ImageSequence.Iterator(im):
                frames.append(_pil_rgb(frame, max_side))
                durations.append(frame.info.get("duration"))
                if max_frames is not None and len(frames) >= max_frames + skip:
                    break
    except Exception as exc:
        raise UserInputError(f"{path}: cannot read the gif ({type(exc).__name__}: {exc})") from None
    known = [d for d in durations if d]
    if not known:
        return frames[skip:], None
    # GIF writers (Pillow included) merge identical consecutive frames into one frame
    # shown for several frame times; repeat such frames so frame times stay uniform.
    base = float(min(known))
    repeats = [max(1, int(round(d / base))) if d else 1 for d in durations]
    frames = [frame for frame, n in zip(frames, repeats, strict=True) for _ in range(n)][skip:]
    if max_frames is not None:
        frames = frames[:max_frames]
    return frames, 1000.0 / base


def _read_image_folder(
    path: Path, max_frames: int | None, max_side: int | None = None, skip: int = 0
) -> list[np.ndarray]:
    from PIL import Image, ImageOps

    files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise UserInputError(f"{path}: the folder holds no images ({', '.join(sorted(IMAGE_SUFFIXES))})")
    frames = []
    for f in files[skip : None if max_frames is None else skip + max_frames]:
        try:
            with Image.open(f) as im:  # a phone's photo: upright as its EXIF orientation says
                frames.append(_pil_rgb(ImageOps.exif_transpose(im), max_side))
        except Exception as exc:
            raise UserInputError(f"{f}: cannot read image ({exc})") from None
    if len({fr.shape for fr in frames}) > 1:
        raise UserInputError(f"{path}: the images differ in size; all frames must be the same size")
    return frames


def resample(clip: Clip, fps: float) -> Clip:
    """Resample to ``fps`` by nearest-frame sampling at the new frame times.

    Duration is kept: ``n_out = round(T * fps / clip.fps)``.
    """
    if abs(clip.fps - fps) < 1e-6:
        return clip
    n_out = max(1, int(round(clip.n_frames * fps / clip.fps)))
    times = np.arange(n_out) / fps
    idx = np.clip(np.round(times * clip.fps).astype(int), 0, clip.n_frames - 1)
    return Clip(clip.frames[idx], float(fps))


#: Frames summed at a time by :func:`grid_luminance`: the 25-s phone clip as float32 at once
#: took 4 GB and 14 s.
GRID_CHUNK = 64


def grid_luminance(frames: np.ndarray, grid: int) -> np.ndarray:
    """``(T, rows, cols)`` mean luminance (the channels' mean, grey levels) of each cell of a
    ``grid`` × ``grid`` division of ``(T, H, W[, C])`` uint8 frames (fewer cells where a side
    has fewer pixels): a picture of what moves that sensor noise averages out of."""
    frames = np.asarray(frames)
    height, width = frames.shape[1:3]
    rows = np.linspace(0, height, min(grid, height) + 1).astype(int)
    cols = np.linspace(0, width, min(grid, width) + 1).astype(int)
    sums = [_cell_sums(frames[start : start + GRID_CHUNK], rows, cols) for start in range(0, len(frames), GRID_CHUNK)]
    return np.concatenate(sums) / np.outer(np.diff(rows), np.diff(cols))[None]


def _cell_sums(frames: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """``(T, rows, cols)`` sums of luminance (the channels' mean) over the grid cells of ``frames``."""
    channels = frames.shape[3] if frames.ndim == 4 else 1
    # Channels and columns summed in one pass along each contiguous row (pixel-interleaved).
    flat = frames.reshape(*frames.shape[:2], -1)
    by_column = np.add.reduceat(flat, cols[:-1] * channels, axis=2, dtype=np.uint32)
    return np.add.reduceat(by_column, rows[:-1], axis=1).astype(np.float64) / channels


def to_gray(frames: np.ndarray) -> np.ndarray:
    """``(T, H, W, 3)`` uint8 → ``(T, H, W)`` float32 luma in [0, 1] (ITU-R BT.601)."""
    f = frames.astype(np.float32) / 255.0
    if f.shape[-1] == 1:
        return f[..., 0]
    return f[..., 0] * 0.299 + f[..., 1] * 0.587 + f[..., 2] * 0.114


def center_crop_resize(frames: np.ndarray, size: int | tuple[int, int]) -> np.ndarray:
    """Centre-crop to the target aspect ratio, then resize (area/bilinear via Pillow).

    Args:
        frames: ``(T, H, W)`` float32 or ``(T, H, W, C)`` uint8.
        size: Output ``(H, W)`` or a single side for square output.

    Returns:
        Frames of the same kind with spatial size ``size``.
    """
    from PIL import Image

    out_h, out_w = (size, size) if isinstance(size, int) else size
    h, w = frames.shape[1:3]
    if (h, w) == (out_h, out_w):
        return frames
    target_aspect = out_w / out_h
    if w / h > target_aspect:
        cw, ch = int(round(h * target_aspect)), h
    else:
        cw, ch = w, int(round(w / target_aspect))
    y0, x0 = (h - ch) // 2, (w - cw) // 2
    cropped = frames[:, y0 : y0 + ch, x0 : x0 + cw]
    resized = []
    for fr in cropped:
        mode = "F" if fr.dtype == np.float32 and fr.ndim == 2 else None
        im = Image.fromarray(fr, mode=mode) if mode else Image.fromarray(fr)
        resized.append(np.asarray(im.resize((out_w, out_h), Image.Resampling.BILINEAR, reducing_gap=2.0)))
    return np.stack(resized).astype(frames.dtype, copy=False)  # float frames come back float32: no copy


def prepare_for_embedding(clip: Clip, *, fps: float, n_frames: int, size: int) -> np.ndarray:
    """Resample, check length, take the first ``n_frames``, grayscale, crop and resize.

    Returns:
        ``(n_frames, size, size)`` float32 in [0, 1].

    Raises:
        UserInputError: when the clip is shorter than ``n_frames`` at ``fps``.
    """
    clip = resample(clip, fps)
    if clip.n_frames < n_frames:
        raise UserInputError(
            f"the clip is too short: {clip.n_frames} frames at {fps:g} fps "
            f"({clip.n_frames / fps:.2f} s); the embedder needs at least {n_frames} frames "
            f"({n_frames / fps:.2f} s)"
        )
    return center_crop_resize(to_gray(clip.frames[:n_frames]), size)


def write_video(
    path: str | Path,
    frames: np.ndarray | Clip,
    fps: float | None = None,
    *,
    lossless: bool = False,
    crf: int = 18,
) -> Path:
    """Write ``(T, H, W, 3)`` uint8 frames as mp4 (H.264, yuv420p) or gif, atomically.

    Odd frame sizes are padded by one pixel for H.264.

    ``lossless``: H.264 in RGB without loss (``libx264rgb``, quantiser 0; a 200-frame 112-px
    flag clip takes 1.5 MB against 71 kB): reading it back gives these frames exactly. ``crf``:
    the lossy quality (18 near-transparent; phones write about 23-28). libx264 reads bytes
    nobody wrote (in PyAV's frames past a width not a multiple of 16, and in heap memory of
    its own); glibc fills them with zeros while a video is written
    (:func:`physinfer.zeroed_heap.zero_filled_allocations`), so the same frames give the same
    file every time. Elsewhere than glibc the lossy path is not repeatable.
    """
    if isinstance(frames, Clip):
        frames, fps = frames.frames, frames.fps if fps is None else fps
    if fps is None:
        raise ValueError("fps is required")
    if not FPS_RANGE[0] <= fps <= FPS_RANGE[1]:  # mp4's time base would round it (to 24 fps)
        raise ValueError(f"cannot write {fps:g} fps: videos are written at {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g} fps")
    path = Path(path)
    frames = _to_rgb(np.asarray(frames))
    suffix = path.suffix.lower()
    with atomic_path(path, suffix=suffix) as tmp:
        if suffix == ".gif":
            _write_gif(tmp, frames, fps)
        elif suffix in VIDEO_SUFFIXES:
            with zero_filled_allocations():
                _write_pyav(tmp, frames, fps, lossless, crf)
        else:
            raise UserInputError(f"{path}: write .mp4 or .gif, not {suffix!r}")
    return path


def round_trip(clip: Clip, crf: int = 18) -> Clip:
    """``clip`` written as H.264 at ``crf`` (as :func:`write_video` writes a target) and read
    back: what a clip looks like once it has been a file. A temporary file, deleted at once."""
    with tempfile.TemporaryDirectory(prefix="physinfer-round-trip-") as folder:
        back = read_video(write_video(Path(folder) / "clip.mp4", clip, crf=crf), fps=clip.fps)
    height, width = np.asarray(clip.frames).shape[1:3]
    return Clip(back.frames[: len(clip.frames), :height, :width], clip.fps)


def _write_pyav(path: Path, frames: np.ndarray, fps: float, lossless: bool = False, crf: int = 18) -> None:
    from fractions import Fraction

    import av

    pad_h, pad_w = frames.shape[1] % 2, frames.shape[2] % 2
    if pad_h or pad_w:
        frames = np.pad(frames, ((0, 0), (0, pad_h), (0, pad_w), (0, 0)), mode="edge")
    rate = Fraction(fps).limit_denominator(1001)
    with av.open(str(path), mode="w", format="mp4") as container:
        stream = container.add_stream("libx264rgb" if lossless else "libx264", rate=rate)
        stream.width, stream.height = frames.shape[2], frames.shape[1]
        stream.pix_fmt = "rgb24" if lossless else "yuv420p"
        stream.options = {"qp": "0", "preset": "veryfast"} if lossless else {"crf": str(int(crf)), "preset": "veryfast"}
        for fr in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(fr, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def _write_gif(path: Path, frames: np.ndarray, fps: float) -> None:
    from PIL import Image

    images = [Image.fromarray(f) for f in frames]
    images[0].save(
        path, format="GIF", save_all=True, append_images=images[1:], duration=int(round(1000 / fps)), loop=0
    )


def side_by_side(clips: Sequence[Clip], height: int = 224) -> Clip:
    """Place clips next to each other (resized to ``height``), at the first clip's fps.

    Clips are resampled to a common rate and cut to the shortest duration.
    """
    fps = clips[0].fps
    resampled = [resample(c, fps) for c in clips]
    n = min(c.n_frames for c in resampled)
    panels = []
    for c in resampled:
        h, w = c.size
        panels.append(center_crop_resize(c.frames[:n], (height, max(2, int(round(w * height / h))))))
    return Clip(np.concatenate(panels, axis=2), fps)
