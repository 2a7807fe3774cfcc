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
        from physinfer.io import atomic_save_npz

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
