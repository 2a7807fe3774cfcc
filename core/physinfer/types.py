"""Value types passed between the roles: :class:`Trajectory` and :class:`Clip`.

Both are plain frozen dataclasses over numpy arrays, so they move cheaply between
processes and save to NPZ without pickling.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.errors import UserInputError
from physinfer.io import atomic_save_npz

#: Frame rates a user may give (``--fps``) or a trajectory file may record: a video is written
#: at these faithfully (below 0.1 fps the mp4 time base rounds to 0, and was written at 24).
FPS_RANGE = (0.1, 1000.0)


def check_fps(fps: Any, option: str = "--fps") -> float:
    """Refuse a frame rate that is not a number from 0.1 to 1000 frames per second.

    The one check of every frame rate a user gives (``render``, ``prepare``, ``refine``,
    ``diagnose``, ``infer`` ``--fps``) or a trajectory file records.

    Args:
        fps: The value.
        option: How it is named in the message (``"--fps"``, ``"t.npz records"``).

    Raises:
        UserInputError: not a positive finite number, or outside :data:`FPS_RANGE`.
    """
    low, high = FPS_RANGE
    try:
        value = float(fps)
    except (TypeError, ValueError):
        raise UserInputError(f"{option} {fps!r} is not a frame rate; give a positive number of frames per second") from None
    if not (np.isfinite(value) and value > 0):
        raise UserInputError(f"{option} {value:g} is not a frame rate; give a positive number of frames per second")
    if not low <= value <= high:
        raise UserInputError(f"{option} {value:g}: give a frame rate from {low:g} to {high:g} frames per second")
    return value


@dataclass(frozen=True)
class Trajectory:
    """A simulated motion: a mesh whose vertices move over time.

    Attributes:
        vertices: ``(T, V, 3)`` float32 vertex positions in metres, one row per output frame.
        faces: ``(F, 3)`` int32 vertex indices of triangles (constant over time).
        fps: Output frame rate in Hz (frames are ``1 / fps`` seconds apart).
        extras: Named float/int arrays the renderer may use (e.g. ``"uv"`` ``(V, 2)``,
            ``"pole"`` endpoints); saved alongside in NPZ.
    """

    vertices: np.ndarray
    faces: np.ndarray
    fps: float
    extras: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.vertices.ndim != 3 or self.vertices.shape[2] != 3:
            raise ValueError(f"vertices must be (T, V, 3), got {self.vertices.shape}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise ValueError(f"faces must be (F, 3), got {self.faces.shape}")
        if self.fps <= 0:
            raise ValueError(f"fps must be positive, got {self.fps}")

    @property
    def n_frames(self) -> int:
        """Number of frames ``T``."""
        return int(self.vertices.shape[0])

    @property
    def duration(self) -> float:
        """Duration in seconds, ``T / fps``."""
        return self.n_frames / self.fps

    def is_finite(self) -> bool:
        """True when no vertex coordinate is NaN or infinite."""
        return bool(np.isfinite(self.vertices).all())

    def save(self, path: str | Path) -> None:
        """Write an NPZ with ``vertices``, ``faces``, ``fps`` and ``extra_<name>`` arrays (atomic)."""
        arrays: dict[str, Any] = {
            "vertices": self.vertices.astype(np.float32),
            "faces": self.faces.astype(np.int32),
            "fps": np.asarray(self.fps, dtype=np.float64),
        }
        arrays.update({f"extra_{k}": np.asarray(v) for k, v in self.extras.items()})
        atomic_save_npz(path, **arrays)

    @classmethod
    def load(cls, path: str | Path) -> Trajectory:
        """Read a trajectory written by :meth:`save` (no pickles are loaded)."""
        try:
            with np.load(path, allow_pickle=False) as data:
                extras = {k[6:]: data[k] for k in data.files if k.startswith("extra_")}
                return cls(data["vertices"], data["faces"], float(data["fps"]), extras)
        except (OSError, KeyError, ValueError) as exc:
            raise UserInputError(f"cannot read trajectory {path}: {exc}") from None


@dataclass(frozen=True)
class Clip:
    """A video clip in memory.

    Attributes:
        frames: ``(T, H, W, C)`` uint8 frames, ``C`` = 3 (RGB) or 1 (grayscale).
        fps: Frame rate in Hz.
    """

    frames: np.ndarray
    fps: float

    def __post_init__(self) -> None:
        if self.frames.ndim != 4 or self.frames.shape[3] not in (1, 3):
            raise ValueError(f"frames must be (T, H, W, C) with C in (1, 3), got {self.frames.shape}")
        if self.frames.dtype != np.uint8:
            raise ValueError(f"frames must be uint8, got {self.frames.dtype}")
        if self.fps <= 0:
            raise ValueError(f"fps must be positive, got {self.fps}")

    @property
    def n_frames(self) -> int:
        """Number of frames ``T``."""
        return int(self.frames.shape[0])

    @property
    def size(self) -> tuple[int, int]:
        """``(H, W)``."""
        return int(self.frames.shape[1]), int(self.frames.shape[2])

    @property
    def duration(self) -> float:
        """Duration in seconds."""
        return self.n_frames / self.fps

    def cropped(self, box: tuple[float, float, float, float]) -> Clip:
        """The clip inside ``box`` = ``(x, y, w, h)`` in its pixels (rounded; clipped at the frame)."""
        x, y, w, h = (int(round(v)) for v in box)
        return Clip(self.frames[:, max(0, y) : y + h, max(0, x) : x + w], self.fps)
