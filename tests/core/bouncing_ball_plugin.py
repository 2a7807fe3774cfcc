"""A ball bouncing on the floor, written as a newcomer writes a plugin from the docs: the
restitution and the drop height are θ, the effect ``ball_drag`` adds quadratic air drag
(``drag_k``, off at 0). Drag and restitution trade off along a ridge — both take height off
each bounce — which is what the discrepancy workflow's effect search must get past
(issue 46). Effect names are global and the real-footage pendulum already registers
``air_drag``, so this one is ``ball_drag``. A small numpy renderer (64 × 64, a soft red disc over a grey floor) and the
built-in ``grid_spectrum`` embedder keep a trial at a few milliseconds.

Registered in code: :func:`ball_registry` (picklable, so a diagnosis' workers can build it
when this folder is importable).
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

G = 9.81
FPS = 25.0
SECONDS = 4.0
RADIUS = 0.1
SPACE = ParameterSpace(
    [
        ParameterSpec("restitution", (0.3, 0.95), description="bounce speed ratio e"),
        ParameterSpec("height", (0.5, 2.0), "m", description="drop height of the ball's bottom"),
    ]
)
TRUTH = {"restitution": 0.7, "height": 1.7}


class AirDrag(Effect):
    """Quadratic air drag ``a = −k |v| v``; off at ``k = 0``."""

    name = "ball_drag"
    description = "air drag growing with the square of the ball's speed"
    phenomenon = "bouncing_ball"
    parameter_space = ParameterSpace(
        [ParameterSpec("drag_k", (0.0, 1.5), "1/m", description="quadratic drag k", default=0.0)]
    )

    def term(self, state, params, t):
        _z, v = state
        return -params["drag_k"] * abs(v) * v


class BallSimulator(Simulator):
    """The ball's height over time: gravity, the effects' terms, and bounces that keep a
    fraction ``e`` of the speed (1 ms steps, sampled at 25 fps); deterministic."""

    def __init__(self, effects: Sequence[Effect] = (), seconds: float = SECONDS) -> None:
        self.effects = tuple(effects)
        self.seconds = seconds
        space = SPACE
        for effect in self.effects:
            space = space.merged(effect.parameter_space)
        self.parameter_space = space

    def heights(self, params) -> np.ndarray:
        """``(T,)`` height of the ball's bottom at each frame."""
        params = self.parameter_space.complete(params)
        n = int(round(self.seconds * FPS))
        per = 40
        h = 1.0 / (FPS * per)
        z, v, e = float(params["height"]), 0.0, float(params["restitution"])
        out = np.empty(n)
        for i in range(n):
            out[i] = z
            for _ in range(per):
                a = -G + sum(effect.term((z, v), params, 0.0) for effect in self.effects)
                v += h * a
                z += h * v
                if z < 0.0 and v < 0.0:
                    z, v = -z * e, -v * e
        return out

    def simulate(self, params, *, seed=0):
        z = self.heights(params) + RADIUS
        corners = RADIUS * np.array([[1, 0, 0], [-1, 0, 0], [0, 0, 1], [0, 0, -1]], dtype=float)
        vertices = corners[None] + np.stack([0 * z, 0 * z, z], axis=1)[:, None]
        faces = np.array([[0, 2, 1], [0, 1, 3]], dtype=np.int32)
        return Trajectory(vertices.astype(np.float32), faces, FPS)


class BallRenderer(Renderer):
    """A soft red disc over a grey floor, seen from the side; ζ: ``size`` (16–256 px)."""

    default_render_params = {"size": 64}

    def render(self, trajectory, render_params=None):
        zeta = self.check_render_params(render_params)
        size = int(zeta["size"])
        if not 16 <= size <= 256:
            from physinfer.errors import UserInputError

            raise UserInputError(f"render setting size={size}: give 16 to 256 pixels")
        scale = size / 2.4  # pixels per metre: the frame spans 2.4 m
        rows, cols = np.mgrid[0:size, 0:size] + 0.5
        x = (cols - size / 2) / scale
        z = (size - rows) / scale - 0.2  # the floor 0.2 m above the bottom edge
        background = np.where(z < 0, 0.45, 0.9)[..., None] * np.ones(3)
        red = np.array([0.85, 0.1, 0.1])
        frames = np.empty((trajectory.n_frames, size, size, 3), dtype=np.uint8)
        for i, verts in enumerate(trajectory.vertices):
            centre = verts.mean(axis=0)
            r = np.hypot(x - centre[0], z - centre[2])
            cover = np.clip(0.5 + (RADIUS - r) * scale, 0.0, 1.0)[..., None]  # antialiased edge
            frames[i] = np.clip((background * (1 - cover) + red * cover) * 255, 0, 255).astype(np.uint8)
        return Clip(frames, trajectory.fps)


def _default_target() -> Target:
    clip = BallRenderer().render(BallSimulator().simulate(TRUTH))
    return Target(clip=clip, truth=dict(TRUTH), render_params={"size": 64}, description="bouncing ball")


def make_phenomenon() -> Phenomenon:
    return Phenomenon(
        name="bouncing_ball",
        description="a ball bouncing on the floor (tests)",
        parameter_space=SPACE,
        make_simulator=lambda effects=(): BallSimulator(effects),
        make_renderer=BallRenderer,
        default_embedder="grid_spectrum",
        default_target=_default_target,
        effects=("ball_drag",),
        default_steps=20,
    )


class BallPlugin:
    """The plugin object: the phenomenon and its effect."""

    @hookimpl
    def physinfer_register_phenomena(self, registry):
        registry.add_phenomenon("bouncing_ball", make_phenomenon, "a ball bouncing on the floor (tests)")

    @hookimpl
    def physinfer_register_effects(self, registry):
        registry.add_effect("ball_drag", AirDrag, "bouncing_ball", AirDrag.description)


def ball_registry():
    """The installed plugins plus the bouncing ball."""
    from physinfer.plugins import load_registry

    return load_registry(extra_plugins={"bouncing_ball": BallPlugin()})[0]


def ball_target(params, path=None, size: int = 64):
    """A target clip at ``params`` (``drag_k`` switches the drag in), written to ``path`` if given."""
    effects = [AirDrag()] if params.get("drag_k", 0.0) > 0 else []
    clip = BallRenderer().render(BallSimulator(effects).simulate(params), {"size": size})
    if path is None:
        return clip
    from physinfer.video import write_video

    return write_video(path, clip)
