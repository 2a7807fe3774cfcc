"""Tiny synthetic datasets of moving sinusoid patterns, for tests and smoke runs.

Each "simulation" is a travelling plane wave whose temporal frequency (Hz) and direction
(radians) play the role of θ. A simulation seed perturbs them slightly (like the flag's
chaotic realisations of one θ), and each "render" varies nuisance factors — spatial
phase, wavelength, contrast, brightness, noise — like camera and texture do for flags.
So the same structure as FlagSim is there (renders of a simulation, simulations of a θ),
with ground truth known exactly and clips made in milliseconds.
"""

from __future__ import annotations

import numpy as np

from physinfer_flag.sdn.data import ArrayDataset

THETA_NAMES = ("frequency_hz", "direction_rad")


def grating_wave(
    *,
    frequency_hz: float,
    direction_rad: float,
    n_frames: int,
    size: int,
    fps: float,
    wavelength_px: float,
    phase: float,
) -> np.ndarray:
    """``sin`` of a travelling plane wave, ``(T, size, size)`` float64 in [-1, 1]."""
    t = np.arange(n_frames, dtype=np.float64)[:, None, None] / fps
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    along = x * np.cos(direction_rad) + y * np.sin(direction_rad)
    return np.sin(2 * np.pi * (along / wavelength_px - frequency_hz * t) + phase)


def to_uint8(video: np.ndarray) -> np.ndarray:
    """Intensities in [0, 1] → uint8 (clipped)."""
    return np.clip(np.rint(video * 255.0), 0, 255).astype(np.uint8)


def moving_grating(
    *,
    frequency_hz: float,
    direction_rad: float,
    n_frames: int,
    size: int,
    fps: float,
    wavelength_px: float,
    phase: float = 0.0,
    contrast: float = 0.4,
    brightness: float = 0.5,
    noise: float = 0.0,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """One clip of a travelling sinusoidal grating.

    Args:
        frequency_hz: Temporal frequency of every pixel's oscillation.
        direction_rad: Direction of travel (0 = along +x).
        n_frames: ``T``.
        size: Side of the square frames.
        fps: Frame rate.
        wavelength_px: Spatial period in pixels.
        phase: Spatial phase offset in radians.
        contrast: Amplitude of the sinusoid (intensity units, 0–1).
        brightness: Mean intensity.
        noise: Standard deviation of added Gaussian pixel noise.
        rng: Generator for the noise.

    Returns:
        ``(T, size, size)`` uint8 grayscale clip.
    """
    wave = grating_wave(
        frequency_hz=frequency_hz,
        direction_rad=direction_rad,
        n_frames=n_frames,
        size=size,
        fps=fps,
        wavelength_px=wavelength_px,
        phase=phase,
    )
    video = brightness + contrast * wave
    if noise > 0:
        video = video + (rng or np.random.default_rng(0)).normal(0.0, noise, video.shape)
    return to_uint8(video)


def grating_dataset(
    *,
    n_thetas: int,
    seeds_per_theta: int = 1,
    renders_per_sim: int = 4,
    n_frames: int = 16,
    size: int = 32,
    fps: float = 25.0,
    frequency_range: tuple[float, float] = (1.0, 8.0),
    seed_jitter: float = 0.03,
    noise: float = 0.02,
    contrast_range: tuple[float, float] = (0.2, 0.45),
    distractor: float = 0.0,
    seed: int = 0,
) -> ArrayDataset:
    """A FlagSim-shaped dataset of moving gratings.

    Args:
        n_thetas: Distinct θ = (frequency, direction).
        seeds_per_theta: Simulations per θ (each seed jitters θ by ``seed_jitter``).
        renders_per_sim: Clips per simulation (different nuisance factors).
        n_frames: Frames per clip.
        size: Side of the square clips.
        fps: Frame rate.
        frequency_range: Range of temporal frequencies, Hz.
        seed_jitter: Relative perturbation of θ between seeds of one θ.
        noise: Pixel noise standard deviation.
        contrast_range: Range of the grating's amplitude (a nuisance factor).
        distractor: Relative amplitude of a second grating of random frequency and
            direction over the lower half of each render (a nuisance that moves, like a
            background); 0 for none.
        seed: Seed of everything.

    Returns:
        A ``"clips"`` :class:`ArrayDataset` with ``sim_ids``, ``group_ids`` (θ index) and
        θ = (frequency_hz, direction_rad) of the θ (not the jittered value).
    """
    rng = np.random.default_rng(seed)
    clips, sims, groups, thetas = [], [], [], []
    sim = 0
    for g in range(n_thetas):
        frequency = rng.uniform(*frequency_range)
        direction = rng.uniform(0.0, np.pi)
        for _ in range(seeds_per_theta):
            f_sim = frequency * (1.0 + seed_jitter * rng.standard_normal())
            d_sim = direction + seed_jitter * rng.standard_normal()
            for _ in range(renders_per_sim):
                contrast = rng.uniform(*contrast_range)
                wave = grating_wave(
                    frequency_hz=f_sim,
                    direction_rad=d_sim,
                    n_frames=n_frames,
                    size=size,
                    fps=fps,
                    wavelength_px=rng.uniform(0.25, 0.5) * size,
                    phase=rng.uniform(0, 2 * np.pi),
                )
                video = rng.uniform(0.4, 0.6) + contrast * wave
                if distractor > 0:
                    other = grating_wave(
                        frequency_hz=rng.uniform(*frequency_range),
                        direction_rad=rng.uniform(0.0, np.pi),
                        n_frames=n_frames,
                        size=size,
                        fps=fps,
                        wavelength_px=rng.uniform(0.25, 0.5) * size,
                        phase=rng.uniform(0, 2 * np.pi),
                    )
                    video[:, size // 2 :] += distractor * contrast * other[:, size // 2 :]
                clips.append(to_uint8(video + rng.normal(0.0, noise, video.shape)))
                sims.append(sim)
                groups.append(g)
                thetas.append((frequency, direction))
            sim += 1
    return ArrayDataset(
        inputs=np.stack(clips),
        sim_ids=np.asarray(sims, dtype=np.int64),
        theta=np.asarray(thetas, dtype=np.float64),
        theta_names=THETA_NAMES,
        group_ids=np.asarray(groups, dtype=np.int64),
        kind="clips",
        fps=fps,
    )
