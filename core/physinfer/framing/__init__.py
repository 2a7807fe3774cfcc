"""Prepare real footage for refinement: find the moving subject, steady the camera, frame it.

A phone video of a flag is not what a renderer makes: the flag sits somewhere in a wide
frame, the camera shakes, the frame rate is 30 or 60 fps. :func:`prepare_clip` turns it
into a clip framed as the phenomenon's renderer frames its subject, so that a refinement
compares like with like (the steps in order: :mod:`physinfer.framing.clip`):

1. **Camera shake** (:mod:`physinfer.framing.shake`): each frame's global shift against
   the middle frame, by phase correlation on the static background (the moving region
   masked out), refined to 1/20 px by a local upsampled DFT (Guizar-Sicairos et al. 2008).
   A shake under :data:`MIN_SHAKE_RMS_PX` is left alone (resampling would only blur).
2. **The moving region** (:mod:`physinfer.framing.region`): the mean absolute difference
   of consecutive steadied frames (motion energy), smoothed, thresholded relative to its
   own distribution (median and MAD of the map; seeds at a fraction of the peak, grown down
   to a lower level, as hysteresis thresholding does), the strongest connected component's
   bounding box.
3. **Framing**: the phenomenon's rule maps that box to the square its renderer frames
   (:attr:`physinfer.roles.Phenomenon.framing`; :func:`default_framing` otherwise).
4. **Crop, scale, trim, resample** (:mod:`physinfer.framing.frames`): every frame is cut
   at the square moved by its shift (sub-pixel, Pillow's bilinear resize with a box),
   scaled to ``size`` × ``size``, the kept span trimmed, the static background frozen
   (noise and compression flicker removed where nothing moves,
   :mod:`physinfer.static_background`), and the frames resampled to ``fps``
   (:func:`physinfer.video.resample`).

Everything is reported in a :class:`PreparedClip` (box and square in the input's pixels,
per-frame shifts, shake and residual shake in pixels, frames kept, warnings;
:mod:`physinfer.framing.settings`), and :func:`save_overlay`
(:mod:`physinfer.framing.overlay`) draws the box and the square on a frame for the user to
check. Refuses (:mod:`physinfer.framing.checks`), with one line each: a static video, a
video in which nothing stands out as moving (with the ``--roi`` way out), a subject that
leaves the frame for most of the clip, a region of interest outside the frame. numpy,
scipy and Pillow only.

For the refinement workflows (``refine``/``diagnose``/``infer``): call
``prepare_clip(read_video(path, fps), framing=phenomenon.framing or default_framing,
settings=PrepareSettings(size=embedder.size, fps=embedder.fps))`` and refine against
``result.clip``; record ``result.to_dict()`` in the run. The submodules' names are
re-exported here.
"""

from __future__ import annotations

from physinfer.framing.checks import check_not_static, check_roi, check_square, trim_range
from physinfer.framing.clip import prepare_clip
from physinfer.framing.frames import ANALYSIS_SIDE, analysis_frames, crop_square
from physinfer.framing.overlay import overlay_figure, save_overlay
from physinfer.framing.region import (
    MIN_CONTRAST,
    MIN_SIGNIFICANCE,
    edge_fraction,
    energy_stats,
    find_moving_box,
    motion_energy,
)
from physinfer.framing.settings import (
    DEFAULT_MARGIN,
    Box,
    FramingRule,
    PreparedClip,
    PrepareSettings,
    default_framing,
)
from physinfer.framing.shake import (
    MIN_SHAKE_RMS_PX,
    background_change,
    background_weight,
    estimate_shifts,
    measure_shake,
    rms_about_mean,
    shift_frames,
    valid_mask,
)

__all__ = [
    "ANALYSIS_SIDE",
    "DEFAULT_MARGIN",
    "MIN_CONTRAST",
    "MIN_SHAKE_RMS_PX",
    "MIN_SIGNIFICANCE",
    "Box",
    "FramingRule",
    "PrepareSettings",
    "PreparedClip",
    "analysis_frames",
    "background_change",
    "background_weight",
    "check_not_static",
    "check_roi",
    "check_square",
    "crop_square",
    "default_framing",
    "edge_fraction",
    "energy_stats",
    "estimate_shifts",
    "find_moving_box",
    "measure_shake",
    "motion_energy",
    "prepare_clip",
    "rms_about_mean",
    "overlay_figure",
    "save_overlay",
    "shift_frames",
    "trim_range",
    "valid_mask",
]
