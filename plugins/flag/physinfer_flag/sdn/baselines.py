"""Comparison networks for the wind-speed table, written in plain torch.

- :class:`ResNet18Frames`: a ResNet-18 applied to every frame, its final activations
  averaged over time (late fusion, Karpathy et al. 2014), as the paper's multi-frame
  ResNet-18 baseline (11.2 M parameters).
- :class:`CNNLSTM`: after Yang, Liang & Lin 2017 ("Learning-based cloth material
  recovery from video"): an AlexNet-style per-frame CNN whose fc7 features feed an LSTM;
  the last hidden state is the clip's feature. The paper gives no layout; AlexNet's
  convolutions and fc6/fc7 with an LSTM of 448 hidden units reproduce the 66.4 M
  parameters it reports.
- :class:`SpectralPooling`: the parameter-free spectral baseline — the SDN's fixed
  front end pooled over a spatial grid (log mean peak power and power-weighted mean
  peak frequency per cell).

Each maps a batch to ``(N, out_dim)`` features; a regression head from
:mod:`physinfer_flag.sdn.evaluation` turns them into a wind speed. Widths are settings,
so tests can build small versions. The two learned baselines read grayscale clips
``(N, T, H, W)`` (uint8 or float in [0, 1]); the spectral one reads front-end features.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from physinfer.errors import UserInputError
from physinfer_flag.sdn.frontend import FrontEndConfig
from physinfer_flag.sdn.network import BasicBlock


def _frames(video: torch.Tensor, n_frames: int) -> torch.Tensor:
    """First ``n_frames`` of ``(N, T, H, W)`` clips, as zero-centred floats."""
    if video.ndim != 4 or video.shape[1] < n_frames:
        raise UserInputError(
            f"expected grayscale clips (N, T>={n_frames}, H, W), got {tuple(video.shape)}"
        )
    x = video[:, :n_frames]
    x = x.float() / 255.0 if x.dtype == torch.uint8 else x.float()
    return (x - 0.5) / 0.25


@dataclass(frozen=True)
class ResNetFramesConfig:
    """Settings of :class:`ResNet18Frames`.

    Attributes:
        n_frames: Frames read per clip (the paper: 1, 10 or 20).
        widths: Channels of the four stages (ResNet-18: 64, 128, 256, 512).
        blocks: Basic blocks per stage (ResNet-18: 2, 2, 2, 2).
    """

    n_frames: int = 20
    widths: tuple[int, int, int, int] = (64, 128, 256, 512)
    blocks: tuple[int, int, int, int] = (2, 2, 2, 2)

    def validate(self) -> None:
        """Raise :class:`ValueError` on inconsistent settings."""
        if self.n_frames < 1 or any(w < 1 for w in self.widths) or any(b < 1 for b in self.blocks):
            raise ValueError("n_frames, widths and blocks must be positive")


class ResNet18Frames(nn.Module):
    """ResNet-18 per frame, temporal average of the pooled activations.

    Args:
        config: Settings.

    Shapes:
        ``(N, T ≥ n_frames, H, W)`` → ``(N, widths[-1])``.
    """

    input_kind = "clips"

    def __init__(self, *, config: ResNetFramesConfig | None = None) -> None:
        super().__init__()
        self.config = config or ResNetFramesConfig()
        self.config.validate()
        w0 = self.config.widths[0]
        self.stem = nn.Sequential(
            nn.Conv2d(1, w0, 7, 2, 3, bias=False),
            nn.BatchNorm2d(w0),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(3, 2, 1),
        )
        stages, channels = [], w0
        for i, (width, n_blocks) in enumerate(
            zip(self.config.widths, self.config.blocks, strict=True)
        ):
            stride = 1 if i == 0 else 2
            blocks = [BasicBlock(channels, width, stride)] + [
                BasicBlock(width, width) for _ in range(n_blocks - 1)
            ]
            stages.append(nn.Sequential(*blocks))
            channels = width
        self.stages = nn.Sequential(*stages)

    @property
    def out_dim(self) -> int:
        """Feature size (the last stage's width)."""
        return self.config.widths[-1]

    def forward(self, video: torch.Tensor) -> torch.Tensor:
        """Clip features ``(N, out_dim)``."""
        x = _frames(video, self.config.n_frames)
        n, t, h, w = x.shape
        y = self.stages(self.stem(x.reshape(n * t, 1, h, w)))
        return y.mean(dim=(2, 3)).reshape(n, t, -1).mean(dim=1)


@dataclass(frozen=True)
class CNNLSTMConfig:
    """Settings of :class:`CNNLSTM` (AlexNet-sized by default).

    Attributes:
        n_frames: Frames read per clip (Yang et al.: 10).
        conv_widths: Channels of the five convolutions.
        fc_width: Width of fc6 and fc7.
        hidden: LSTM hidden size (the clip feature size); 448 gives the paper's 66.4 M
            parameters in total.
        dropout: Dropout before fc6 and fc7 during training.
    """

    n_frames: int = 10
    conv_widths: tuple[int, int, int, int, int] = (96, 256, 384, 384, 256)
    fc_width: int = 4096
    hidden: int = 448
    dropout: float = 0.5

    def validate(self) -> None:
        """Raise :class:`ValueError` on inconsistent settings."""
        if (
            self.n_frames < 1
            or self.fc_width < 1
            or self.hidden < 1
            or any(c < 1 for c in self.conv_widths)
        ):
            raise ValueError("n_frames, conv_widths, fc_width and hidden must be positive")
        if not 0 <= self.dropout < 1:
            raise ValueError("dropout must be in [0, 1)")


class CNNLSTM(nn.Module):
    """Per-frame AlexNet-style CNN, an LSTM over its fc7 features, the last hidden state.

    Args:
        config: Settings.

    Shapes:
        ``(N, T ≥ n_frames, H, W)`` → ``(N, hidden)``.
    """

    input_kind = "clips"
    #: Smallest input side the AlexNet stack accepts: its stride-4 convolution and three
    #: stride-2 poolings of width 3 leave nothing to pool below 63 px.
    min_side = 63

    def __init__(self, *, config: CNNLSTMConfig | None = None) -> None:
        super().__init__()
        self.config = config or CNNLSTMConfig()
        self.config.validate()
        c1, c2, c3, c4, c5 = self.config.conv_widths
        self.features = nn.Sequential(
            nn.Conv2d(1, c1, 11, 4, 2),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(3, 2),
            nn.Conv2d(c1, c2, 5, 1, 2),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(3, 2),
            nn.Conv2d(c2, c3, 3, 1, 1),
            nn.ReLU(inplace=True),
            nn.Conv2d(c3, c4, 3, 1, 1),
            nn.ReLU(inplace=True),
            nn.Conv2d(c4, c5, 3, 1, 1),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(3, 2),
            nn.AdaptiveAvgPool2d(6),
        )
        fc = self.config.fc_width
        self.fc = nn.Sequential(
            nn.Dropout(self.config.dropout),
            nn.Linear(c5 * 36, fc),
            nn.ReLU(inplace=True),
            nn.Dropout(self.config.dropout),
            nn.Linear(fc, fc),
            nn.ReLU(inplace=True),
        )
        self.lstm = nn.LSTM(fc, self.config.hidden, batch_first=True)

    @property
    def out_dim(self) -> int:
        """Feature size (the LSTM hidden size)."""
        return self.config.hidden

    def forward(self, video: torch.Tensor) -> torch.Tensor:
        """Clip features ``(N, hidden)``: the LSTM's last hidden state."""
        x = _frames(video, self.config.n_frames)
        n, t, h, w = x.shape
        if min(h, w) < self.min_side:
            raise UserInputError(f"CNN+LSTM needs frames of at least {self.min_side} px per side, got {h}x{w}")
        per_frame = self.fc(self.features(x.reshape(n * t, 1, h, w)).flatten(1)).reshape(n, t, -1)
        _, (hidden, _) = self.lstm(per_frame)
        return hidden[-1]


class SpectralPooling(nn.Module):
    """The parameter-free spectral baseline: front-end maps pooled over a grid.

    For every power/frequency channel pair of the front end and every grid cell: the
    log of the mean peak power, and the power-weighted mean peak frequency in Hz.

    Args:
        frontend: Settings of the front end whose features are pooled.
        grid: Cells per side.
        power_floor: Added to the mean power before the log.

    Shapes:
        ``(N, 4k, h, w)`` front-end features → ``(N, 4k · grid²)``.
    """

    input_kind = "features"

    def __init__(
        self, *, frontend: FrontEndConfig | None = None, grid: int = 7, power_floor: float = 1e-6
    ) -> None:
        super().__init__()
        if grid < 1 or power_floor <= 0:
            raise ValueError("grid and power_floor must be positive")
        self.frontend_config = frontend or FrontEndConfig()
        self.grid, self.power_floor = grid, power_floor

    @property
    def out_dim(self) -> int:
        """Feature size."""
        return self.frontend_config.out_channels * self.grid**2

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """Pooled features ``(N, out_dim)``."""
        half = self.frontend_config.out_channels // 2
        if features.ndim != 4 or features.shape[1] != 2 * half:
            raise UserInputError(
                f"expected front-end features (N, {2 * half}, h, w), got {tuple(features.shape)}"
            )
        power, hz = features[:, :half].clamp_min(0), features[:, half:]
        mean_power = F.adaptive_avg_pool2d(power, self.grid)
        weighted_hz = F.adaptive_avg_pool2d(power * hz, self.grid) / mean_power.clamp_min(1e-12)
        return torch.cat([torch.log(mean_power + self.power_floor), weighted_hz], dim=1).flatten(1)
