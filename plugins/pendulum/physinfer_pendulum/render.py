"""Renders the pendulum with pyrender as a person films one: the camera frames the swing.

A bob on a thin string in front of a plain wall, seen from the front. The camera looks at the
middle of the bob's path and is placed so that the path fills ``fill`` of the frame's width
(a phone held up to the swing); with ``pivot_in_view`` it steps back to show the pivot too.
What the host compares is the bob's motion (the ``motion`` embedder), so the look parameters
(colours, light, the camera's tilt) exist to check that they do not matter.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from physinfer import Clip, Renderer, Trajectory
from physinfer.rendering import OffscreenContext, look_at, segment_pose, use_headless_gl
from physinfer.settings import MappingSettings, check_range


@dataclass(frozen=True)
class PendulumRenderParams(MappingSettings):
    """Render parameters ζ of :class:`PendulumRenderer`; every field is a ζ key.

    Attributes:
        size: Side of the square frames in pixels, 16 to 1024.
        fill: Share of the frame's width the bob's path spans, 0.1 to 0.9.
        pivot_in_view: Show the pivot (the camera steps back), 0 or 1.
        elevation_deg: Camera tilt above the swing's plane, -30 to 30 degrees.
        yfov_deg: Vertical field of view in degrees, 10 to 90.
        light: Directional light intensity, 0 to 100.
        wall: Wall grey level, 0 to 1.
        bob_hue: Bob colour as a hue, 0 to 1 (0: red, 0.33: green, 0.66: blue).
    """

    settings_noun: ClassVar[str] = "render parameter"
    settings_owner: ClassVar[str] = "pendulum"

    size: int = 64
    fill: float = 0.5
    pivot_in_view: int = 0
    elevation_deg: float = 0.0
    yfov_deg: float = 40.0
    light: float = 4.0
    wall: float = 0.85
    bob_hue: float = 0.0

    def validate(self) -> None:
        """Check every value (finite, in range) before anything is rendered.

        Raises:
            UserInputError: naming the offending key and its range.
        """
        check_range("size", self.size, 16, 1024)
        check_range("fill", self.fill, 0.1, 0.9)
        check_range("pivot_in_view", self.pivot_in_view, 0, 1)
        check_range("elevation_deg", self.elevation_deg, -30.0, 30.0)
        check_range("yfov_deg", self.yfov_deg, 10.0, 90.0)
        check_range("light", self.light, 0.0, 100.0)
        check_range("wall", self.wall, 0.0, 1.0)
        check_range("bob_hue", self.bob_hue, 0.0, 1.0)


def hue_rgb(hue: float) -> list[float]:
    """A saturated colour of the given hue, RGBA."""
    import colorsys

    return [*colorsys.hsv_to_rgb(hue % 1.0, 0.85, 0.8), 1.0]


class PendulumRenderer(Renderer):
    """pyrender renderer of pendulum trajectories (see :class:`PendulumRenderParams` for ζ)."""

    default_render_params: Mapping[str, Any] = MappingProxyType(PendulumRenderParams().to_dict())

    def __init__(self) -> None:
        self._contexts: dict[int, OffscreenContext] = {}

    def render(self, trajectory: Trajectory, render_params: Mapping[str, Any] | None = None) -> Clip:
        """Render all frames; returns ``(T, size, size, 3)`` uint8."""
        use_headless_gl()
        import pyrender
        import trimesh

        zeta = self.check_render_params(render_params)
        size = int(zeta["size"])
        ctx = self._contexts.setdefault(size, OffscreenContext(size, size))
        pivot = np.asarray(trajectory.extras.get("pivot", np.zeros(3)), dtype=float)
        centres = trajectory.vertices.mean(axis=1).astype(float)
        wall = float(zeta["wall"])
        scene = pyrender.Scene(bg_color=[wall, wall, wall * 0.96, 1.0], ambient_light=[0.4, 0.4, 0.4])
        bob = pyrender.Primitive(
            positions=trajectory.vertices[0] - centres[0].astype(np.float32), indices=trajectory.faces,
            material=pyrender.MetallicRoughnessMaterial(baseColorFactor=hue_rgb(float(zeta["bob_hue"])), roughnessFactor=0.6),
            mode=4,
        )  # fmt: skip
        bob_node = scene.add(pyrender.Mesh([bob]))
        length = float(np.linalg.norm(centres[0] - pivot))
        string = trimesh.creation.cylinder(radius=max(0.0015, 0.004 * length), height=1.0, sections=6)
        string_node = scene.add(
            pyrender.Mesh.from_trimesh(
                string, material=pyrender.MetallicRoughnessMaterial(baseColorFactor=[0.15, 0.15, 0.15, 1.0])
            )
        )
        pose = self._camera_pose(centres, pivot, zeta)
        scene.add(pyrender.PerspectiveCamera(yfov=np.radians(float(zeta["yfov_deg"]))), pose=pose)
        scene.add(pyrender.DirectionalLight(intensity=float(zeta["light"])), pose=pose)
        bob_poses = np.tile(np.eye(4), (len(centres), 1, 1))
        bob_poses[:, :3, 3] = centres
        string_poses = np.stack([segment_pose(pivot, centre) for centre in centres])
        frames = ctx.render_sequence(scene, poses={bob_node: bob_poses, string_node: string_poses})
        return Clip(frames, trajectory.fps)

    @staticmethod
    def _camera_pose(centres: np.ndarray, pivot: np.ndarray, zeta: Mapping[str, Any]) -> np.ndarray:
        """Look at the middle of the bob's path from the front (−y), far enough to frame it."""
        low, high = centres.min(axis=0), centres.max(axis=0)
        middle = (low + high) / 2
        length = float(np.linalg.norm(centres[0] - pivot))
        half_width = max((high[0] - low[0]) / 2, 0.25 * length, 0.02) / float(zeta["fill"])
        if zeta["pivot_in_view"]:
            middle = (pivot + middle) / 2
            half_width = max(half_width, 0.7 * (pivot[2] - low[2]))
        distance = half_width / np.tan(np.radians(float(zeta["yfov_deg"])) / 2)
        tilt = np.radians(float(zeta["elevation_deg"]))
        eye = middle + distance * np.array([0.0, -np.cos(tilt), np.sin(tilt)])
        return look_at(eye, middle)

    def sample_render_params(self, rng: np.random.Generator) -> dict[str, Any]:
        """Domain randomisation for datasets: every look a phone video may have (the wall, the
        bob's colour, the light, the framing, the camera's tilt), at the default size."""
        return {
            **self.default_render_params,
            "fill": float(rng.uniform(0.25, 0.8)),
            "pivot_in_view": int(rng.random() < 0.3),
            "elevation_deg": float(rng.uniform(-15.0, 15.0)),
            "light": float(rng.uniform(2.0, 8.0)),
            "wall": float(rng.uniform(0.2, 0.95)),
            "bob_hue": float(rng.uniform(0.0, 1.0)),
        }

    def check_render_params(self, render_params: Mapping[str, Any] | None) -> dict[str, Any]:
        """The complete ζ, typed and range-checked (see :class:`PendulumRenderParams`).

        Raises:
            UserInputError: an unknown key, a value of the wrong type or out of range.
        """
        return PendulumRenderParams.from_mapping(render_params).to_dict()

    def close(self) -> None:
        for ctx in self._contexts.values():
            ctx.close()
        self._contexts.clear()

