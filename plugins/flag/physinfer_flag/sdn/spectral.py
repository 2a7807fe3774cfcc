"""The spectral decomposition layer of the paper's Algorithm 1.

A video volume ``(N, C, T, H, W)`` is read as ``N·C·H·W`` temporal signals. Each signal
is Hann-windowed and Fourier-transformed along ``T``; its periodogram
``I(ω) = |F(ω)|² / T`` is searched for the ``k`` strongest peaks (local maxima; for
``k = 1`` simply the strongest bin), and their powers and frequencies (in Hz, hence the
frame rate) are returned as a 2D feature map ``(N, 2kC, H, W)``: the ``kC`` power
channels first, then the ``kC`` frequency channels, channel index ``c·k + i`` for peak
``i`` of input channel ``c``.

Two interchangeable implementations: ``"fft"`` (``torch.fft.rfft``, the literal
algorithm, kept as the reference) and ``"matmul"`` (the window, the optional mean
removal and the DFT folded into one ``(T, 2F)`` real matrix applied by one GEMM, which
is faster for the short signals used here and fuses with the fixed filters in front).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Literal

import torch
from torch import nn

from physinfer.errors import UserInputError

Method = Literal["fft", "matmul"]


@dataclass(frozen=True)
class SpectralSettings:
    """Settings of the spectral decomposition.

    Attributes:
        k: Number of periodogram peaks kept per signal.
        fps: Sampling rate of the signals in Hz (frequencies are reported in Hz).
        detrend: Subtract each signal's temporal mean before windowing, so that a static
            edge does not win every peak at 0 Hz (scipy's ``detrend="constant"``). The
            paper does not mention it; ``False`` gives the literal algorithm.
        exclude_dc: Never select the 0 Hz bin as a peak.
        n_fft: DFT length (zero-padding when larger than ``T``); ``None`` uses ``T``.
        method: ``"matmul"`` (fused DFT matrix) or ``"fft"`` (``torch.fft.rfft``).
    """

    k: int = 1
    fps: float = 25.0
    detrend: bool = True
    exclude_dc: bool = True
    n_fft: int | None = None
    method: Method = "matmul"

    def validate(self) -> None:
        """Raise :class:`ValueError` on inconsistent settings."""
        if self.k < 1:
            raise ValueError(f"k must be at least 1, got {self.k}")
        if not (math.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"fps must be positive, got {self.fps}")
        if self.n_fft is not None and self.n_fft < 2:
            raise ValueError(f"n_fft must be at least 2, got {self.n_fft}")
        if self.method not in ("fft", "matmul"):
            raise ValueError(f"method must be 'fft' or 'matmul', got {self.method!r}")

    def dft_length(self, n_frames: int) -> int:
        """The DFT length used for signals of ``n_frames`` samples."""
        n_fft = n_frames if self.n_fft is None else self.n_fft
        if n_fft < n_frames:
            raise UserInputError(
                f"n_fft={n_fft} is shorter than the clip ({n_frames} frames); raise n_fft"
            )
        return n_fft

    def first_bin(self) -> int:
        """Index of the lowest periodogram bin a peak may sit in."""
        return 1 if self.exclude_dc else 0

    def n_candidate_bins(self, n_frames: int) -> int:
        """How many bins the peaks are searched among."""
        return self.dft_length(n_frames) // 2 + 1 - self.first_bin()


def hann_window(
    n_frames: int, *, dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu"
) -> torch.Tensor:
    """The periodic (DFT-even) Hann window, as scipy's spectral estimators use.

    Returns:
        ``(T,)`` window.
    """
    return torch.hann_window(n_frames, periodic=True, dtype=dtype, device=device)


def frequencies_hz(settings: SpectralSettings, n_frames: int) -> torch.Tensor:
    """Frequencies in Hz of the candidate bins, ``(F,)`` float64."""
    n_fft = settings.dft_length(n_frames)
    bins = torch.arange(settings.first_bin(), n_fft // 2 + 1, dtype=torch.float64)
    return bins * settings.fps / n_fft


def dft_basis(
    settings: SpectralSettings, n_frames: int, *, dtype: torch.dtype = torch.float64
) -> torch.Tensor:
    """The window, mean removal and real DFT of the candidate bins as one matrix.

    ``signals @ basis`` gives ``[Re F | Im F]`` of the windowed (and detrended) signals,
    so the periodogram is ``(re² + im²) / T``.

    Args:
        settings: Spectral settings.
        n_frames: Signal length ``T``.
        dtype: dtype of the result (built in float64, then cast).

    Returns:
        ``(T, 2F)`` matrix, ``F`` = number of candidate bins.
    """
    return _dft_basis_float64(settings, n_frames).to(dtype)


@lru_cache(maxsize=32)
def _dft_basis_float64(settings: SpectralSettings, n_frames: int) -> torch.Tensor:
    n_fft = settings.dft_length(n_frames)
    t = torch.arange(n_frames, dtype=torch.float64)
    bins = torch.arange(settings.first_bin(), n_fft // 2 + 1, dtype=torch.float64)
    angle = 2.0 * math.pi * torch.outer(t, bins) / n_fft  # (T, F)
    dft = torch.cat([torch.cos(angle), -torch.sin(angle)], dim=1)  # (T, 2F)
    window = hann_window(n_frames, dtype=torch.float64)
    # Row-scaling by the window, then the mean removal applied before it: x ↦ w ⊙ (x − x̄).
    basis = window[:, None] * dft
    if settings.detrend:
        basis = basis - basis.mean(dim=0, keepdim=True)
    return basis


def periodogram(signals: torch.Tensor, settings: SpectralSettings) -> torch.Tensor:
    """Periodogram ``|F(ω)|² / T`` of the candidate bins, along the last axis.

    Args:
        signals: ``(..., T)`` real signals.
        settings: Spectral settings (``method`` picks the implementation).

    Returns:
        ``(..., F)`` powers, bins as in :func:`frequencies_hz`.
    """
    n_frames = signals.shape[-1]
    if settings.method == "fft":
        x = signals - signals.mean(dim=-1, keepdim=True) if settings.detrend else signals
        x = x * hann_window(n_frames, dtype=x.dtype, device=x.device)
        spectrum = torch.fft.rfft(x, n=settings.dft_length(n_frames), dim=-1)[
            ..., settings.first_bin() :
        ]
        return (spectrum.real.square() + spectrum.imag.square()) / n_frames
    basis = dft_basis(settings, n_frames, dtype=signals.dtype).to(signals.device)
    return power_from_coefficients(signals @ basis, n_frames)


def power_from_coefficients(
    coefficients: torch.Tensor, n_frames: int, dim: int = -1
) -> torch.Tensor:
    """``(re² + im²) / T`` from stacked ``[Re | Im]`` DFT coefficients along ``dim``.

    Args:
        coefficients: ``(..., 2F, ...)`` real and imaginary parts stacked along ``dim``.
        n_frames: Signal length ``T``.
        dim: The axis holding the ``2F`` coefficients.

    Returns:
        ``(..., F, ...)`` periodogram.
    """
    re, im = coefficients.chunk(2, dim=dim)
    return (re.square() + im.square()) / n_frames


def select_peaks(
    power: torch.Tensor, settings: SpectralSettings, n_frames: int, dim: int = -1
) -> tuple[torch.Tensor, torch.Tensor]:
    """The ``k`` strongest peaks of a periodogram and their frequencies in Hz.

    For ``k = 1`` this is the strongest bin. For ``k > 1`` only local maxima count as
    peaks, so that the bins beside a strong peak (the Hann window's main lobe spreads a
    tone over three bins) are not reported as further peaks; when a signal has fewer
    than ``k`` local maxima, the missing peaks have power 0 at 0 Hz.

    Args:
        power: ``(..., F, ...)`` periodogram, bins along ``dim``.
        settings: Spectral settings (``k``, ``fps``, the bin layout).
        n_frames: Signal length ``T``.
        dim: The frequency axis.

    Returns:
        ``(peak_power, peak_hz)``, each shaped like ``power`` with ``dim`` of size ``k``,
        strongest first.
    """
    if settings.k > power.shape[dim]:
        raise UserInputError(
            f"k={settings.k} peaks requested but only {power.shape[dim]} frequency bins exist "
            f"for {n_frames} frames; lower k or use longer clips"
        )
    step = settings.fps / settings.dft_length(n_frames)
    if settings.k == 1:
        values, index = power.max(dim=dim, keepdim=True)
        return values, (index + settings.first_bin()).to(power.dtype) * step
    p = power.movedim(dim, -1)
    edge = torch.full_like(p[..., :1], -torch.inf)
    left, right = torch.cat([edge, p[..., :-1]], -1), torch.cat([p[..., 1:], edge], -1)
    # ">=" on one side and ">" on the other: a flat top counts once.
    peaks = torch.where((p >= left) & (p > right), p, -torch.inf)
    values, index = peaks.topk(settings.k, dim=-1, largest=True, sorted=True)
    hz = (index + settings.first_bin()).to(power.dtype) * step
    missing = torch.isinf(values)
    values = torch.where(missing, torch.zeros_like(values), values)
    hz = torch.where(missing, torch.zeros_like(hz), hz)
    return values.movedim(-1, dim), hz.movedim(-1, dim)


def spectral_decomposition(x: torch.Tensor, settings: SpectralSettings) -> torch.Tensor:
    """Algorithm 1: top-``k`` periodogram peaks and frequencies of every pixel signal.

    Args:
        x: ``(N, C, T, H, W)`` video volume (float).
        settings: Spectral settings.

    Returns:
        ``(N, 2kC, H, W)``: ``kC`` power maps, then ``kC`` frequency maps in Hz.
    """
    if x.ndim != 5:
        raise UserInputError(
            f"the spectral layer takes (N, C, T, H, W), got shape {tuple(x.shape)}"
        )
    n, c, t, h, w = x.shape
    k = settings.k
    if settings.method == "fft":
        signals = x.permute(0, 1, 3, 4, 2)  # (N, C, H, W, T)
        power = periodogram(signals, settings)
        values, hz = select_peaks(power, settings, t, dim=-1)  # (N, C, H, W, k)
        values, hz = values.permute(0, 1, 4, 2, 3), hz.permute(0, 1, 4, 2, 3)
    else:
        # T stays in place: basisᵀ (2F, T) @ (N, C, T, HW) needs no transpose of the video.
        basis = dft_basis(settings, t, dtype=x.dtype).to(x.device)
        coefficients = basis.T @ x.reshape(n, c, t, h * w)  # (N, C, 2F, HW)
        power = power_from_coefficients(coefficients, t, dim=2)
        values, hz = select_peaks(power, settings, t, dim=2)  # (N, C, k, HW)
    return torch.cat([values.reshape(n, c * k, h, w), hz.reshape(n, c * k, h, w)], dim=1)


class SpectralDecomposition(nn.Module):
    """The spectral decomposition layer as a module (no trainable weights).

    Args:
        settings: Spectral settings (``k``, ``fps``, windowing, method).

    Shapes:
        input ``(N, C, T, H, W)`` → output ``(N, 2kC, H, W)``.
    """

    def __init__(self, *, settings: SpectralSettings | None = None) -> None:
        super().__init__()
        self.settings = settings or SpectralSettings()
        self.settings.validate()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Apply :func:`spectral_decomposition`."""
        return spectral_decomposition(x, self.settings)

    def extra_repr(self) -> str:
        """Settings shown by ``print(module)``."""
        s = self.settings
        return f"k={s.k}, fps={s.fps:g}, detrend={s.detrend}, exclude_dc={s.exclude_dc}, method={s.method!r}"
