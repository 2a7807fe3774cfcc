"""The picture ``physinfer prepare`` writes for the user to check its framing by eye."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from physinfer.framing.settings import PreparedClip
from physinfer.io import atomic_path


def save_overlay(result: PreparedClip, path: str | Path) -> Path:
    """:func:`overlay_figure` as a PNG, written atomically."""
    fig = overlay_figure(result)
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png")
    return path


def overlay_figure(result: PreparedClip) -> Any:
    """The reference frame with the moving box (or roi) and the cropped square drawn (a
    matplotlib figure, no pyplot state)."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    height, width = result.input_size
    fig = Figure(figsize=(8, 8 * height / width), dpi=max(100, width / 8))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.imshow(result.preview)
    x, y, w, h = result.box
    label = "moving region" if result.roi_source == "found" else "--roi"
    ax.add_patch(Rectangle((x, y), w, h, fill=False, edgecolor="yellow", linewidth=2, label=label))
    sx, sy, side, _ = result.square
    ax.add_patch(
        Rectangle(
            (sx, sy),
            side,
            side,
            fill=False,
            edgecolor="red",
            linewidth=2,
            linestyle="--",
            label="framing (cropped)",
        )
    )
    ax.set_xlim(min(0, sx) - 1, max(width, sx + side) + 1)
    ax.set_ylim(max(height, sy + side) + 1, min(0, sy) - 1)
    ax.legend(loc="lower right", fontsize=9, framealpha=0.8)
    ax.text(
        0.01,
        0.99,
        f"box {', '.join(f'{v:.0f}' for v in result.box)}  shake {result.shake_rms_px:.2f} px rms",
        transform=ax.transAxes,
        va="top",
        color="white",
        fontsize=9,
        bbox={"facecolor": "black", "alpha": 0.6, "pad": 2},
    )
    ax.axis("off")
    return fig
