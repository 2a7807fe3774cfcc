"""A block on a horizontal spring, a second newcomer plugin for the ridge benchmark (issue 46):
θ is the natural frequency, a viscous damping rate and the start offset; the effect
``dry_friction`` adds Coulomb friction (a constant deceleration ``mu_g`` against the motion,
off at 0). Dry friction takes amplitude off linearly and stops the block, viscous damping
takes it off exponentially: over a few swings they trade off, as drag and restitution do on
the bouncing ball. Written from docs/writing-a-plugin.md alone; a small numpy renderer
(64 × 64, a blue square over a grey table) and the built-in ``grid_spectrum`` embedder.

Registered in code: :func:`friction_registry` (picklable, so a diagnosis' workers can build
it when this folder is importable).
"""

from __future__ import annotations

from collections.abc import Sequence

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
from physinfer.roles import Effect

FPS = 25.0
SECONDS = 6.0
HALF = 0.1  # the block's half width, m
SPACE = ParameterSpace(
    [
        ParameterSpec("freq_hz", (0.4, 1.5), "Hz", description="natural frequency"),
        ParameterSpec("damping", (0.0, 0.6), "1/s", description="viscous damping rate"),
        ParameterSpec("offset", (0.2, 0.8), "m", description="start offset"),
    ]
)
TRUTH = {"freq_hz": 0.8, "damping": 0.15, "offset": 0.6}


class DryFriction(Effect):
    """Coulomb friction: a deceleration ``mu_g`` against the velocity; off at 0."""

    name = "dry_friction"
    description = "Coulomb friction of the block on its table"
    phenomenon = "spring_block"
    parameter_space = ParameterSpace(
        [
            ParameterSpec(
                "mu_g", (0.0, 1.0), "m/s^2", description="friction deceleration", default=0.0
            )
        ]
    )

    def term(self, state, params, t):
        _x, v = state
        return 0.0 if abs(v) < 1e-4 else -params["mu_g"] * float(np.sign(v))


class BlockSimulator(Simulator):
    """The block's position over time (1 ms steps, sampled at 25 fps); deterministic. A block
    at rest stays there while friction can hold it against the spring."""

    def __init__(self, effects: Sequence[Effect] = ()) -> None:
        self.effects = tuple(effects)
        space = SPACE
        for effect in self.effects:
            space = space.merged(effect.parameter_space)
        self.parameter_space = space

    def positions(self, params) -> np.ndarray:
        p = self.parameter_space.complete(params)
        w, c = 2 * np.pi * float(p["freq_hz"]), float(p["damping"])
        x, v = float(p["offset"]), 0.0
        n, per = int(round(SECONDS * FPS)), 40
        h = 1.0 / (FPS * per)
        out = np.empty(n)
        for i in range(n):
            out[i] = x
            for _ in range(per):
                if self.effects and abs(v) < 1e-4 and p["mu_g"] >= w * w * abs(x):
                    v = 0.0  # static friction holds the block
                    continue
                extra = sum(effect.term((x, v), p, 0.0) for effect in self.effects)
                v += h * (-w * w * x - 2 * c * v + extra)
                x += h * v
        return out

    def simulate(self, params, *, seed=0):
        x = self.positions(params)
        corners = HALF * np.array([[1, 0, 1], [-1, 0, 1], [-1, 0, -1], [1, 0, -1]], dtype=float)
        vertices = corners[None] + np.stack([x, 0 * x, 0 * x], axis=1)[:, None]
        faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
        return Trajectory(vertices.astype(np.float32), faces, FPS)


class BlockRenderer(Renderer):
    """A blue square over a grey table, seen from the front; ζ: ``size`` (16–256 px)."""

    default_render_params = {"size": 64}

    def render(self, trajectory, render_params=None):
        zeta = self.check_render_params(render_params)
        size = int(zeta["size"])
        if not 16 <= size <= 256:
            from physinfer.errors import UserInputError

            raise UserInputError(f"render setting size={size}: give 16 to 256 pixels")
        scale = size / 2.2  # pixels per metre: the frame spans 2.2 m
        rows, cols = np.mgrid[0:size, 0:size] + 0.5
        x = (cols - size / 2) / scale
        z = (size / 2 - rows) / scale
        background = np.where(z < -HALF, 0.4, 0.85)[..., None] * np.ones(3)
        blue = np.array([0.1, 0.2, 0.8])
        frames = np.empty((trajectory.n_frames, size, size, 3), dtype=np.uint8)
        for i, verts in enumerate(trajectory.vertices):
            reach = np.maximum(np.abs(x - verts[:, 0].mean()), np.abs(z))
            cover = np.clip(0.5 + (HALF - reach) * scale, 0.0, 1.0)[..., None]  # antialiased edge
            frames[i] = np.clip((background * (1 - cover) + blue * cover) * 255, 0, 255).astype(
                np.uint8
            )
        return Clip(frames, trajectory.fps)


def _default_target() -> Target:
    return Target.synthetic(
        BlockSimulator(), BlockRenderer(), TRUTH, seed=0, description="block on a spring"
    )


def make_phenomenon() -> Phenomenon:
    return Phenomenon(
        name="spring_block",
        description="a block on a spring (tests)",
        parameter_space=SPACE,
        make_simulator=lambda effects=(): BlockSimulator(effects),
        make_renderer=BlockRenderer,
        default_embedder="grid_spectrum",
        default_target=_default_target,
        effects=("dry_friction",),
        default_steps=20,
    )


class FrictionPlugin:
    """The plugin object: the phenomenon and its effect."""

    @hookimpl
    def physinfer_register_phenomena(self, registry):
        registry.add_phenomenon("spring_block", make_phenomenon, "a block on a spring (tests)")

    @hookimpl
    def physinfer_register_effects(self, registry):
        registry.add_effect("dry_friction", DryFriction, "spring_block", DryFriction.description)


def friction_registry():
    """The installed plugins plus the block on a spring."""
    from physinfer.plugins import load_registry

    return load_registry(extra_plugins={"spring_block": FrictionPlugin()})[0]


def friction_target(params, path=None, size: int = 64):
    """A target clip at ``params`` (``mu_g`` switches the friction in), written to ``path`` if given."""
    effects = [DryFriction()] if params.get("mu_g", 0.0) > 0 else []
    clip = BlockRenderer().render(BlockSimulator(effects).simulate(params), {"size": size})
    if path is None:
        return clip
    from physinfer.video import write_video

    return write_video(path, clip)
