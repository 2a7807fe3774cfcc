"""What a pendulum video tells before any simulation: its period, hence its length.

The tracked path's frequency ``f`` gives the small-angle length ``L₀ = g / (2π f)²``. It is
read by fitting a damped sinusoid to the path (a grid of frequencies around the spectrum's
peak, the amplitude, phase, decay and offset solved by least squares at each): the same as
the spectral peak on a long clip, and still right on a clip of about one swing, where the
spectrum's peak is as wide as the frequency itself. A larger swing has a longer period, so the true
length lies between ``L₀`` over the period factor of the largest amplitude in θ's range and
a little above ``L₀``: :func:`video_estimate` returns that interval as the search box.
"""

from __future__ import annotations

import numpy as np

from physinfer.types import Clip

G = 9.81
#: Relative uncertainty of a frequency read from one cycle (it shrinks with the cycles seen),
#: and its floor and ceiling: the length box spans (1 ± slack)² around the estimate.
SLACK_ONE_CYCLE, SLACK_MIN, SLACK_MAX = 0.3, 0.03, 0.5
#: The amplitude read from the arc's curvature is searched up to this factor above it (camera
#: tilt foreshortens the rise; a visible string pulls the centroid towards the pivot) …
ANGLE_FACTOR = 1.8
#: … and at least up to this angle (degrees). A string that enters from the frame's top edge
#: lifts the centroid as the bob sinks and hides part of a moderate swing's rise: on 8-s renders
#: of the default look (pivot out of view) 10° swings read as 1.7°, 4.5° and 4.2° and a 20° one
#: as 10.5° (lengths 0.3, 1, 2.5 and 2.5 m), boxes that left the truth out; the pivot in view,
#: 10° read as 2.0° once. Larger swings read within the factor.
ANGLE_BOX_FLOOR = 25.0
#: Decay rates (1/s) of the swing's amplitude tried by the fit; the damping is twice the rate.
DECAY_RATES = (0.0, 0.01, 0.025, 0.05, 0.1, 0.15, 0.2, 0.3)
#: Where the search starts for a swing smaller than the bob (its curvature unreadable).
SMALL_SWING_DEG = 5.0


def period_factor(amplitude_deg: float) -> float:
    """``T(amplitude) / T₀`` of an undamped pendulum (the series to θ⁴)."""
    theta = np.radians(amplitude_deg)
    return float(1 + theta**2 / 16 + 11 * theta**4 / 3072)


def dominant_frequency(u: np.ndarray, fps: float) -> float:
    """The strongest frequency of ``u`` in Hz (zero-padded, parabolic peak interpolation)."""
    n = len(u)
    n_fft = max(1 << 15, 1 << int(np.ceil(np.log2(16 * n))))
    power = np.abs(np.fft.rfft((u - u.mean()) * np.hanning(n), n_fft)) ** 2
    k = int(np.argmax(power[1:])) + 1
    if 1 <= k < len(power) - 1:
        a, b, c = np.log(power[k - 1 : k + 2] + 1e-300)
        k = k + 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) < 0 else k
    return float(k * fps / n_fft)


def _fit(signal: np.ndarray, t: np.ndarray, frequency: float, rate: float) -> tuple[float, np.ndarray]:
    """Least-squares fit of a decaying sinusoid with offset and drift: (residual, coefficients)."""
    envelope = np.exp(-rate * t)
    basis = np.stack([envelope * np.cos(2 * np.pi * frequency * t), envelope * np.sin(2 * np.pi * frequency * t),
                      np.ones_like(t), t], axis=1)  # fmt: skip
    coef, *_ = np.linalg.lstsq(basis, signal, rcond=None)
    return float(np.sum((basis @ coef - signal) ** 2)), coef


def fitted_swing(u: np.ndarray, fps: float) -> tuple[float, float, float, float]:
    """The damped sinusoid that fits ``u`` best: ``(frequency Hz, decay rate 1/s, amplitude,
    phase in cycles)``, where ``u ≈ amplitude · e^(-rate t) · cos(2π (f t + phase))``."""
    t = np.arange(len(u)) / fps
    duration = len(u) / fps
    peak = dominant_frequency(u, fps)
    low = max(0.3 / duration, 0.5 * peak, 0.05)
    best = (np.inf, peak, 0.0, np.zeros(4))
    for rate in DECAY_RATES:
        for f in np.geomspace(low, min(2.0 * peak, fps / 2.5), 400):
            residual, coef = _fit(u, t, f, rate)
            if residual < best[0]:
                best = (residual, f, rate, coef)
    _, frequency, rate, (a, b, _, _) = best
    # a cos + b sin = A cos(ωt - δ), δ = atan2(b, a); cos(ωt + 2π phase) gives phase = -δ / 2π.
    return float(frequency), float(rate), float(np.hypot(a, b)), float((-np.arctan2(b, a) / (2 * np.pi)) % 1.0)


def swing_angle(u: np.ndarray, v: np.ndarray, fps: float, frequency: float, rate: float) -> float:
    """The swing's angular amplitude (degrees) from the arc's curvature: across the swing the
    bob rises at twice the frequency by ``L(1 - cos φ)``, so ``A_v(2f) / A_u(f) ≈ φ₀ / 4``
    whatever the camera's scale and the pivot's place."""
    t = np.arange(len(u)) / fps
    _, coef_u = _fit(u, t, frequency, rate)
    _, coef_v = _fit(v, t, 2 * frequency, 2 * rate)
    ratio = np.hypot(*coef_v[:2]) / max(np.hypot(*coef_u[:2]), 1e-9)
    return float(np.degrees(4 * ratio))


def video_estimate(clip: Clip, max_amplitude_deg: float = 60.0) -> dict[str, tuple[float, float, float]]:
    """``{name: (value, low, high)}`` for the length (the tracked period), the amplitude (the
    arc's curvature) and the phase, from the motion embedder's track of ``clip``.

    Raises:
        UserInputError: the bob does not cross the middle of its path twice.
    """
    from physinfer.embedders import MotionSpectrumEmbedder
    from physinfer.errors import UserInputError
    from physinfer.tracking import half_swings

    # Two movers were refused on the whole video before framing (conditioning.check_one_subject).
    embedder = MotionSpectrumEmbedder()
    track = embedder.track(clip, allow_shift=True)
    u, v, _ = track.axes()
    crossings, _ = half_swings(u, embedder.fps)
    if crossings < 2:
        raise UserInputError(
            f"the clip ({clip.n_frames / clip.fps:.2f} s) is too short to see a full swing: the bob crosses "
            f"the middle of its path {crossings} time(s); give a clip of at least two swings"
        )
    frequency, rate, _, phase = fitted_swing(u, embedder.fps)
    angle = float(np.clip(swing_angle(u, v, embedder.fps, frequency, rate), 1.0, max_amplitude_deg))
    small_angle = G / (2 * np.pi * frequency) ** 2
    cycles = frequency * clip.n_frames / clip.fps
    slack = float(np.clip(SLACK_ONE_CYCLE / cycles, SLACK_MIN, SLACK_MAX))
    low = small_angle / period_factor(max_amplitude_deg) ** 2 * (1 - slack) ** 2
    if track.method == "centroid":
        # Noise across the swing (a codec, a small image) adds to the rise and reads as a larger
        # angle, never a smaller one: the box keeps every smaller angle (a clean 8-s target of
        # 9.5° read as 33° was fitted at 59° and 7 % short when the box stopped at 18°).
        amplitude = (angle, 1.0, min(max_amplitude_deg, max(angle * ANGLE_FACTOR, ANGLE_BOX_FLOOR)))
    else:  # tracked by image shift (a swing smaller than the bob): no curvature to read
        amplitude = (SMALL_SWING_DEG, 1.0, max_amplitude_deg)
    return {
        "length": (small_angle, low, small_angle * (1 + slack) ** 2),
        "amplitude": amplitude,
        "phase": (phase, 0.0, 1.0),
        "damping": (2 * rate, 0.0, 0.5),
    }
