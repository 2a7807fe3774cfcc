"""An embedder's fingerprint: its embedding of a fixed synthetic probe clip.

Estimators (the posterior's, the render-parameter estimator) record the fingerprint of the
embedder they were trained with; at inference the embedder is rebuilt and must reproduce it,
so an estimator used with other weights or another embedder is refused instead of silently
wrong.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from physinfer.types import Clip


def probe_clip(n_frames: int, fps: float, size: int = 96) -> Any:
    """A fixed synthetic clip (drifting, flickering blobs): the embedder fingerprint's input.

    Returns:
        A :class:`~physinfer.types.Clip` of ``n_frames`` RGB frames at ``fps``.
    """
    t = np.arange(n_frames, dtype=np.float64)[:, None, None] / fps
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float64) / size
    wave = (
        np.sin(2 * np.pi * (3 * xx + 1.3 * t))
        + np.cos(2 * np.pi * (2 * yy - 0.7 * t + xx))
        + 0.5 * np.sin(2 * np.pi * 2.1 * t) * np.exp(-((xx - 0.5) ** 2 + (yy - 0.5) ** 2) * 12)
    )
    gray = np.clip(127.5 + 50.0 * wave, 0, 255).astype(np.uint8)
    return Clip(np.repeat(gray[..., None], 3, axis=-1), fps)


def embedder_probe(embedder: Any) -> np.ndarray:
    """``(E,)`` the embedding of :func:`probe_clip` by ``embedder`` (its fingerprint)."""
    return np.asarray(
        embedder.embed(probe_clip(int(embedder.n_frames), float(embedder.fps))), dtype=np.float64
    )


def probe_mismatch(expected: list[float], actual: np.ndarray) -> float:
    """Relative distance of two probe embeddings (0 for the same embedder and weights)."""
    a, b = np.asarray(expected, dtype=np.float64), np.asarray(actual, dtype=np.float64)
    if a.shape != b.shape:
        return float("inf")
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(a), 1e-12))


#: Largest probe mismatch accepted: float32 differences across devices and BLAS are ~1e-6;
#: another embedder or weights differ by order 1.
PROBE_TOLERANCE = 1e-3
