"""The Spectral Decomposition Network: fixed front end, three ResNet blocks, a linear map.

``SDN = SDNHead ∘ SpectralFrontEnd``. The front end has no trainable weights (see
:mod:`physinfer_flag.sdn.frontend`); everything trainable lives in :class:`SDNHead`,
which reads the cached ``(N, 4k, H/2, W/2)`` spectral maps: log peak power and peak
frequency are normalised by a batch-norm layer, three standard ResNet basic blocks
(stride 2 each) follow, then an average pool to a small spatial grid — keeping where on
the flag the spectral power sits — and one linear layer to ``D_e``.

The paper fixes three ResNet blocks, ``D_e = 512`` and reports 2.6 M parameters; the
widths ``(64, 128, 256)`` and the 3×3 pooling grid are our choice and give 2.4 M.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from physinfer.errors import UserInputError
from physinfer_flag.sdn.frontend import FrontEndConfig, SpectralFrontEnd
from physinfer_flag.sdn.settings import settings_from_dict


@dataclass(frozen=True)
class SDNConfig:
    """Architecture of the SDN.

    Attributes:
        frontend: Settings of the fixed front end (input size, frames, fps, filters, k).
        widths: Output channels of the ResNet basic blocks (each halves the resolution).
        embedding_dim: ``D_e``, the size of the embedding.
        pool_grid: Side of the spatial grid the last feature map is averaged to.
        power_floor: Peak powers enter the network as ``log(power + power_floor)``.
    """

    frontend: FrontEndConfig = field(default_factory=FrontEndConfig)
    widths: tuple[int, ...] = (64, 128, 256)
    embedding_dim: int = 512
    pool_grid: int = 3
    power_floor: float = 1e-6

    def validate(self) -> None:
        """Raise :class:`ValueError` on inconsistent settings."""
        self.frontend.validate()
        if not self.widths or any(w < 1 for w in self.widths):
            raise ValueError(f"widths must be positive channel counts, got {self.widths}")
        if self.embedding_dim < 1 or self.pool_grid < 1:
            raise ValueError("embedding_dim and pool_grid must be positive")
        if self.power_floor <= 0:
            raise ValueError("power_floor must be positive")

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (nested front-end settings)."""
        data = dataclasses.asdict(self)
        data["widths"] = list(self.widths)
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SDNConfig:
        """Rebuild from :meth:`to_dict` output; unknown keys are an error."""
        data = dict(data)
        frontend = FrontEndConfig.from_dict(data.pop("frontend", {}))
        return settings_from_dict(cls, {**data, "frontend": frontend})


class BasicBlock(nn.Module):
    """The ResNet basic block (He et al. 2016): two 3×3 convolutions and a shortcut.

    Shapes:
        ``(N, in_channels, H, W)`` → ``(N, out_channels, ⌈H/stride⌉, ⌈W/stride⌉)``.
    """

    def __init__(self, in_channels: int, out_channels: int, stride: int = 1) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(in_channels, out_channels, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(out_channels)
        self.conv2 = nn.Conv2d(out_channels, out_channels, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(out_channels)
        self.shortcut: nn.Module = nn.Identity()
        if stride != 1 or in_channels != out_channels:
            self.shortcut = nn.Sequential(
                nn.Conv2d(in_channels, out_channels, 1, stride, bias=False),
                nn.BatchNorm2d(out_channels),
            )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Residual block output."""
        y = F.relu(self.bn1(self.conv1(x)))
        return F.relu(self.bn2(self.conv2(y)) + self.shortcut(x))


class SDNHead(nn.Module):
    """The trainable part of the SDN: spectral maps → embedding.

    Args:
        config: Architecture.

    Shapes:
        input ``(N, 4k, H/2, W/2)`` (front-end output) → ``(N, D_e)``.
    """

    input_kind = "features"

    def __init__(self, *, config: SDNConfig) -> None:
        super().__init__()
        config.validate()
        self.config = config
        self.n_power = config.frontend.out_channels // 2
        self.input_norm = nn.BatchNorm2d(config.frontend.out_channels)
        blocks, channels = [], config.frontend.out_channels
        for width in config.widths:
            blocks.append(BasicBlock(channels, width, stride=2))
            channels = width
        self.blocks = nn.Sequential(*blocks)
        self.pool = nn.AdaptiveAvgPool2d(config.pool_grid)
        self.linear = nn.Linear(channels * config.pool_grid**2, config.embedding_dim)

    @property
    def out_dim(self) -> int:
        """``D_e``."""
        return self.config.embedding_dim

    @property
    def frontend_config(self) -> FrontEndConfig:
        """Settings of the front end whose features this head reads."""
        return self.config.frontend

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """Embed front-end features ``(N, 4k, h, w)`` → ``(N, D_e)``."""
        if features.ndim != 4 or features.shape[1] != self.config.frontend.out_channels:
            raise UserInputError(
                f"the SDN head takes front-end features (N, {self.config.frontend.out_channels}, h, w), "
                f"got {tuple(features.shape)}"
            )
        power, hz = features[:, : self.n_power], features[:, self.n_power :]
        # Peak powers span orders of magnitude between a still and a flapping region.
        x = torch.cat([torch.log(power.clamp_min(0) + self.config.power_floor), hz], dim=1)
        x = self.blocks(self.input_norm(x))
        return self.linear(self.pool(x).flatten(1))


class SDN(nn.Module):
    """The Spectral Decomposition Network (front end + :class:`SDNHead`).

    Args:
        config: Architecture (default: the paper's settings).

    Shapes:
        input ``(N, T, H, W)`` grayscale video, uint8 or float in [0, 1], ``T = n_frames``
        (longer clips are cut), ``H = W = size`` → ``(N, D_e)``.
    """

    input_kind = "clips"

    def __init__(self, *, config: SDNConfig | None = None) -> None:
        super().__init__()
        self.config = config or SDNConfig()
        self.config.validate()
        self.frontend = SpectralFrontEnd(config=self.config.frontend)
        self.head = SDNHead(config=self.config)

    @property
    def out_dim(self) -> int:
        """``D_e``."""
        return self.config.embedding_dim

    @property
    def frontend_config(self) -> FrontEndConfig:
        """Settings of the fixed front end."""
        return self.config.frontend

    def forward(self, video: torch.Tensor) -> torch.Tensor:
        """Embed a batch of videos ``(N, T, H, W)`` → ``(N, D_e)``."""
        c = self.config.frontend
        if video.ndim != 4 or video.shape[1] < c.n_frames:
            raise UserInputError(
                f"the SDN takes grayscale videos (N, T>={c.n_frames}, H, W), got {tuple(video.shape)}"
            )
        return self.head(self.frontend(video[:, : c.n_frames]))

    def embed_features(self, features: torch.Tensor) -> torch.Tensor:
        """Embed cached front-end features ``(N, 4k, h, w)`` → ``(N, D_e)``."""
        return self.head(features)


def count_parameters(module: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)
