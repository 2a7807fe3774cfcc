"""A mass on a spring, written as a newcomer writes a plugin from docs/writing-a-plugin.md: a
damped oscillator seen from the side (frequency and damping), a small numpy renderer of a
block hanging from a spring on a plain wall, the built-in ``grid_spectrum`` embedder. Used to
reproduce, end to end, what a user meets when training a posterior for a new phenomenon.
"""

from __future__ import annotations

import numpy as np

from physinfer import (
    Clip,
    ParameterSpace,
    ParameterSpec,
    Phenomenon,
    Renderer,
    Simulator,
    Target,
    Trajectory,
)
from physinfer.hooks import hookimpl

FPS = 25.0
SECONDS = 4.0
SPACE = ParameterSpace(
    [
        ParameterSpec("frequency", (0.4, 2.0), "Hz", description="natural frequency"),
        ParameterSpec("damping", (0.0, 0.3), "1/s", description="amplitude decay rate"),
    ]
)
TRUTH = {"frequency": 1.1, "damping": 0.12}


class SpringSimulator(Simulator):
    """``y(t) = A e^{-γ t} cos(2π f t)``: the block's height below its rest point."""

    parameter_space = SPACE

    def __init__(self, seconds: float = SECONDS) -> None:
        self.seconds = seconds

    def simulate(self, params, *, seed=0):
        t = np.arange(int(round(self.seconds * FPS))) / FPS
        y = 0.25 * np.exp(-params["damping"] * t) * np.cos(2 * np.pi * params["frequency"] * t)
        corners = np.array([[-0.1, -0.1, 0.0], [0.1, -0.1, 0.0], [0.1, 0.1, 0.0], [-0.1, 0.1, 0.0]])
        vertices = corners[None] + np.stack([0 * t, y, 0 * t], axis=1)[:, None]
        return Trajectory(vertices.astype(np.float32), np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32), FPS)


class SpringRenderer(Renderer):
    """A shaded block under a zig-zag spring, 64 × 64 RGB; ζ: wall and block colours, zoom."""

    default_render_params = {"wall": 0.85, "block_hue": 0.0, "zoom": 1.0}

    def sample_render_params(self, rng):
        return {
            "wall": float(rng.uniform(0.6, 0.95)),
            "block_hue": float(rng.uniform(0.0, 1.0)),
            "zoom": float(rng.uniform(0.8, 1.2)),
        }

    def render(self, trajectory, render_params=None):
        zeta = {**self.default_render_params, **(render_params or {})}
        size = 64
        ys, xs = np.mgrid[0:size, 0:size] / size - 0.5  # image coordinates, y down
        hue = 2 * np.pi * zeta["block_hue"]
        block = 0.5 + 0.4 * np.array([np.cos(hue), np.cos(hue - 2.1), np.cos(hue + 2.1)])
        frames = np.empty((trajectory.n_frames, size, size, 3), dtype=np.uint8)
        wall = np.full((size, size, 3), zeta["wall"]) * (1.0 - 0.15 * (ys + 0.5))[..., None]
        for i, v in enumerate(trajectory.vertices):
            centre = 0.1 + float(v[:, 1].mean()) * zeta["zoom"]
            half = 0.1 * zeta["zoom"]
            # soft edges: coverage of each pixel by the block, as a renderer's antialiasing gives
            inside = np.clip(0.5 + (half - np.maximum(np.abs(xs), np.abs(ys - centre))) * size, 0, 1)
            spring = np.clip(1.5 - np.abs(xs - 0.03 * np.sin(40 * ys)) * size, 0, 1) * (ys < centre - half)
            image = wall * (1 - inside[..., None]) + block * inside[..., None]
            image = image * (1 - 0.6 * spring[..., None])
            frames[i] = np.clip(image * 255, 0, 255).astype(np.uint8)
        return Clip(frames, trajectory.fps)


def _default_target() -> Target:
    clip = SpringRenderer().render(SpringSimulator().simulate(TRUTH))
    return Target(clip=clip, truth=dict(TRUTH), description="spring (truth 1.1 Hz, 0.12 1/s)")


def make_phenomenon() -> Phenomenon:
    return Phenomenon(
        name="spring",
        description="a mass on a spring (tests)",
        parameter_space=SPACE,
        make_simulator=lambda effects: SpringSimulator(),
        make_renderer=SpringRenderer,
        default_embedder="grid_spectrum",
        default_target=_default_target,
    )


class SpringPlugin:
    """The plugin object: registers the phenomenon under its name."""

    @hookimpl
    def physinfer_register_phenomena(self, registry):
        registry.add_phenomenon("spring", make_phenomenon, "a mass on a spring (tests)")


def spring_registry():
    """The installed plugins plus the spring."""
    from physinfer.plugins import load_registry

    return load_registry(extra_plugins={"spring": SpringPlugin()})[0]
