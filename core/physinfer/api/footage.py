"""The API's video-in, video-out commands: ``prepare`` (frame real footage as the renderer
frames its subject) and ``render`` (draw another simulator's trajectory through physinfer's
camera). Re-exported by :mod:`physinfer.api`; the CLI's ``prepare`` and ``render`` call them."""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from physinfer.api.options import PrepareOptions, RenderOptions, with_settings
from physinfer.api.plugins import registry
from physinfer.api.results import frames_figure
from physinfer.api.values import required
from physinfer.conditioning import check_window, parse_roi
from physinfer.errors import UserInputError
from physinfer.facing import Facing, face
from physinfer.framing import (
    PrepareSettings,
    default_framing,
    overlay_figure,
    prepare_clip,
    save_overlay,
)
from physinfer.io import atomic_write_json, check_output_file
from physinfer.meshio import load_trajectory
from physinfer.render_estimate import estimate_render_params
from physinfer.scene import bind_scene, resolve_scene
from physinfer.types import Clip, check_fps
from physinfer.video import read_video, write_video


@dataclass
class PreparedVideo:
    """A video framed, steadied and resampled for comparison with simulations.

    Attributes:
        plugin: The phenomenon it was framed for.
        target: The input video.
        embedder: The embedder whose size and frame rate it was prepared for.
        prepared: What :func:`physinfer.framing.prepare_clip` found and made (``clip``,
            ``box``, ``square``, shake, ``warnings``, ...).
        render_estimate: The camera's render parameters read from the prepared clip, with
            their uncertainty (``None``: not asked for).
        paths: Files written (``video``, ``json``, ``overlay``; empty without ``out``).
        facing: Whether the video was mirrored to show the subject the renderer's way round
            (:mod:`physinfer.facing`; then ``box`` and ``square`` are in the mirrored video's
            pixels), or ``None`` when the subject has no side.
    """

    plugin: str
    target: Path
    embedder: str
    prepared: Any
    render_estimate: dict[str, Any] | None
    paths: dict[str, str] = field(default_factory=dict)
    facing: Facing | None = None

    @property
    def clip(self) -> Clip:
        """The prepared clip."""
        return self.prepared.clip

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``physinfer prepare --json`` prints (also written to ``NAME.json``)."""
        return {
            "plugin": self.plugin,
            "target": str(self.target),
            "embedder": self.embedder,
            **self.prepared.to_dict(),
            **({} if self.facing is None else {"facing": self.facing.to_dict()}),
            "render_estimate": self.render_estimate,
            **self.paths,
        }

    def plot(self) -> Any:
        """The reference frame with the box found and the square cropped (a matplotlib
        figure; ``NAME_overlay.png`` is the same drawing)."""
        return overlay_figure(self.prepared)


def _kept_seconds(start: float, end: float | None, duration: float | None) -> float | None:
    """The seconds ``prepare`` keeps from ``start``: ``--duration``, or up to ``--end`` (the
    window ``refine``, ``infer`` and ``diagnose`` take).

    Raises:
        UserInputError: both given, or a window that is no window (:func:`check_window`).
    """
    if end is None:
        return duration
    if duration is not None:
        raise UserInputError(f"--end {end:g} and --duration {duration:g} both say where the part kept ends: give one")
    check_window(start, end)
    return end - start


def prepare(plugin: str, options: PrepareOptions | None = None, **settings: Any) -> PreparedVideo:
    """Find the moving subject in a video, steady the camera, crop it to the renderer's
    framing and resample it to the embedder's frame rate (``physinfer prepare``).

    ``refine``, ``diagnose`` and ``infer`` do the same to a ``target`` that is not square;
    this shows what they would compare with, and writes it when ``out`` is given.

    Args:
        plugin: The phenomenon.
        options: All settings at once; ``settings`` replace its fields.
        **settings: Fields of :class:`PrepareOptions` (``target`` is needed).

    Raises:
        UserInputError: a missing or unreadable video, a bad ``roi`` or trim, a video in
            which no moving subject is found (the message names the ``roi`` way out), an
            ``out`` that is not a video name or would overwrite ``target``, or whose video,
            JSON or overlay exists already (without ``overwrite``; checked before anything
            is read).
    """
    o = with_settings(PrepareOptions, options, settings)
    target = required(o.target, "target", "the video to prepare")
    paths = None if o.out is None else output_paths(Path(o.out), target, overwrite=o.overwrite)
    roi = parse_roi(o.roi) if isinstance(o.roi, str) else o.roi
    # Settings are checked before the embedder (and torch) loads: a typo should cost nothing.
    prepare_settings = PrepareSettings(
        roi=None if roi is None else tuple(float(v) for v in roi),
        start_s=o.start, duration_s=_kept_seconds(o.start, o.end, o.duration), stabilise=not o.no_stabilise,
        freeze_background=not o.no_freeze, size=o.size or 224,
    )  # fmt: skip
    prepare_settings.validate()
    phenomenon = registry().phenomenon(plugin)
    name = o.embedder or phenomenon.default_embedder
    embedder = registry().embedder(name, model=None, device="cpu")
    prepare_settings = replace(
        prepare_settings,
        size=int(o.size if o.size is not None else getattr(embedder, "size", 224)),
        fps=float(embedder.fps),
    )
    prepare_settings.validate()
    clip, roi, facing = face(phenomenon, read_video(target, fps=o.fps), prepare_settings.roi, o.mirror)
    prepared = prepare_clip(
        clip, framing=phenomenon.framing or default_framing, settings=replace(prepare_settings, roi=roi)
    )
    estimate = None
    if not o.no_render_estimate:
        estimate = estimate_render_params(phenomenon, prepared.clip, embedder=embedder)
    video = PreparedVideo(plugin, target, name, prepared, estimate, facing=facing)
    if paths is not None:
        _write_prepared(video, paths)
    return video


def _write_prepared(video: PreparedVideo, paths: dict[str, Path]) -> None:
    write_video(paths["video"], video.clip)
    save_overlay(video.prepared, paths["overlay"])
    video.paths = {name: str(path) for name, path in paths.items()}
    atomic_write_json(paths["json"], video.to_dict())


def output_paths(out: Path, target: Path, *, overwrite: bool = False) -> dict[str, Path]:
    """The video, JSON and overlay paths of ``out``; refuses a bad or clobbering ``out``.

    ``target`` is never written over; an existing video, JSON or overlay is replaced only with
    ``overwrite``; a folder that cannot be written is refused (:func:`check_output_file`).
    """
    if out.suffix.lower() not in (".mp4", ".gif"):
        raise UserInputError(f"--out {out}: write a .mp4 or .gif file")
    paths = {
        "video": out,
        "overlay": out.with_name(f"{out.stem}_overlay.png"),
        "json": out.with_suffix(".json"),
    }
    for path in paths.values():
        if path.is_dir():
            raise UserInputError(f"--out: {path} is a directory; give a file name")
        if target.exists() and path.exists() and path.resolve() == target.resolve():
            raise UserInputError(
                f"--out: writing {path} would overwrite --target; choose another name"
            )
    for path in paths.values():
        shown = f"--out {out}" if path == out else f"--out {out}: {path}"
        check_output_file(path, "--out", overwrite=overwrite, shown=shown)
    return paths


@dataclass
class Rendering:
    """A trajectory file drawn by a phenomenon's renderer.

    Attributes:
        plugin: The phenomenon.
        trajectory: The file or OBJ folder it came from.
        loaded: The :class:`~physinfer.types.Trajectory` read.
        clip: Its rendering.
        render_params: ζ it was rendered with (defaults filled in).
        scene: The scene's settings when given, else ``None``.
        seconds: Time to render.
        paths: Files written (``video``).
    """

    plugin: str
    trajectory: Path
    loaded: Any
    clip: Clip
    render_params: dict[str, Any]
    scene: dict[str, Any] | None
    seconds: float
    paths: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``physinfer render --json`` prints."""
        return {
            "plugin": self.plugin,
            "trajectory": str(self.trajectory),
            "source": "obj" if self.trajectory.is_dir() else "npz",
            "n_frames": self.loaded.n_frames,
            "n_vertices": int(self.loaded.vertices.shape[1]),
            "n_faces": int(self.loaded.faces.shape[0]),
            "fps": self.loaded.fps,
            "uv": "uv" in self.loaded.extras,
            "render_params": self.render_params,
            **({"scene": self.scene} if self.scene is not None else {}),
            "render_s": self.seconds,
            **self.paths,
        }

    def plot(self, n: int = 6) -> Any:
        """``n`` frames of the rendering side by side (a matplotlib figure)."""
        return frames_figure(self.clip, n)


def render(plugin: str, options: RenderOptions | None = None, **settings: Any) -> Rendering:
    """Render a trajectory file, physinfer's NPZ or another simulator's per-frame OBJ meshes
    (``physinfer render``), so other simulators are seen through the same camera and ζ.

    Args:
        plugin: The phenomenon whose renderer draws it.
        options: All settings at once; ``settings`` replace its fields.
        **settings: Fields of :class:`RenderOptions` (``trajectory`` is needed).

    Raises:
        UserInputError: a missing or malformed trajectory (varying vertex counts, missing
            frames, object arrays), an OBJ folder without ``fps``, an ``fps`` (given or
            recorded) outside 0.1-1000, a bad ζ or scene, an ``out`` that is not a video name,
            an existing ``out`` without ``overwrite``.
    """
    o = with_settings(RenderOptions, options, settings)
    trajectory = required(o.trajectory, "trajectory", "a trajectory NPZ or a folder of .obj meshes")
    if o.fps is not None:  # 0.1-1000 fps, before the renderer is made
        check_fps(o.fps)
    out = None if o.out is None else Path(o.out)
    if out is not None:  # the user's video stays theirs: refused before anything is rendered

        if out.suffix.lower() not in (".mp4", ".gif"):
            raise UserInputError(f"--out {out}: write a .mp4 or .gif file")
        check_output_file(out, "--out", overwrite=o.overwrite)
    phenomenon = registry().phenomenon(plugin)
    scene = resolve_scene(phenomenon, dict(o.scene_set))
    renderer = bind_scene(phenomenon, scene).make_renderer()
    try:
        # ζ and the file are checked before any rendering, as simulate checks ζ before simulating.
        zeta = renderer.check_render_params({**renderer.default_render_params, **o.render_set})
        loaded = load_trajectory(trajectory, o.fps)
        t0 = time.perf_counter()
        clip = renderer.render(loaded, zeta)
        seconds = time.perf_counter() - t0
    finally:
        renderer.close()
    rendering = Rendering(plugin, trajectory, loaded, clip, zeta, scene, seconds)
    if out is not None:
        write_video(out, clip)
        rendering.paths["video"] = str(out)
    return rendering
