"""Renders the pendulum with pyrender: a red bob on a dark rod in front of a light wall.

The scene is built once; each frame only the poses of the bob and the rod change (the
bob is rigid, so a translation of its first-frame mesh reproduces every frame).
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
        distance: Camera distance from the pendulum in metres, 0.5 to 50.
        yfov_deg: Vertical field of view in degrees, 5 to 120.
        light: Directional light intensity, 0 to 100.
    """

    settings_noun: ClassVar[str] = "render parameter"
    settings_owner: ClassVar[str] = "pendulum_lab"

    size: int = 128
    distance: float = 3.2
    yfov_deg: float = 50.0
    light: float = 4.0

    def validate(self) -> None:
        """Check every value (finite, in range) before anything is simulated or rendered.

        Raises:
            UserInputError: naming the offending key and its range.
        """
        # A frame of 100000² pixels would ask for terabytes; 0 or fewer pixels is a GL error.
        check_range("size", self.size, 16, 1024)
        check_range("distance", self.distance, 0.5, 50.0)
        check_range("yfov_deg", self.yfov_deg, 5.0, 120.0)
        check_range("light", self.light, 0.0, 100.0)


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
        size = zeta["size"]
        ctx = self._contexts.setdefault(size, OffscreenContext(size, size))
        pivot = np.asarray(trajectory.extras.get("pivot", np.array([0.0, 0.0, 1.8])), dtype=float)

        scene = pyrender.Scene(bg_color=[0.92, 0.92, 0.88, 1.0], ambient_light=[0.35, 0.35, 0.35])
        bob_mat = pyrender.MetallicRoughnessMaterial(baseColorFactor=[0.85, 0.1, 0.1, 1.0], roughnessFactor=0.6)
        prim = pyrender.Primitive(
            positions=trajectory.vertices[0], indices=trajectory.faces, material=bob_mat, mode=4
        )
        bob_node = scene.add(pyrender.Mesh([prim]))
        rest = trajectory.vertices[0].mean(axis=0)
        rod = trimesh.creation.cylinder(radius=0.02, height=1.0)
        rod_node = scene.add(
            pyrender.Mesh.from_trimesh(
                rod, material=pyrender.MetallicRoughnessMaterial(baseColorFactor=[0.1, 0.1, 0.1, 1.0])
            )
        )
        target = pivot - np.array([0.0, 0.0, 0.8])
        eye = target + np.array([0.0, -float(zeta["distance"]), 0.0])
        pose = look_at(eye, target)
        scene.add(pyrender.PerspectiveCamera(yfov=np.radians(float(zeta["yfov_deg"]))), pose=pose)
        scene.add(pyrender.DirectionalLight(intensity=float(zeta["light"])), pose=pose)

        centres = trajectory.vertices.mean(axis=1)
        bob_poses = np.tile(np.eye(4), (trajectory.n_frames, 1, 1))
        bob_poses[:, :3, 3] = centres - rest
        rod_poses = np.stack([segment_pose(pivot, centre) for centre in centres])
        frames = ctx.render_sequence(scene, poses={bob_node: bob_poses, rod_node: rod_poses})
        return Clip(frames, trajectory.fps)

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

