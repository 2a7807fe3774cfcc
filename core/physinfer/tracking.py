"""Track the one thing that moves in a clip: its foreground mask and the path of its centre.

Real footage differs from a render in every look (a textured ball against a wall, a red bob
against grey), but not in how the subject moves. This module reduces a clip to that motion:

- the background is each pixel's temporal median (a subject that passes a pixel less than
  half of the time leaves the wall there);
- a pixel is foreground where it differs from the background by more than the clip's own
  noise (a robust spread of all differences) allows;
- a pixel that is foreground most of the time is not the subject's path but something that
  changes in place (a flickering dial, a lamp, a screen): such pixels are dropped, so the
  track follows what travels;
- the track is the difference-weighted centroid of the remaining foreground per frame, in
  the clip's pixels, and its principal axes (the swing and across it); a swing smaller than
  the subject (whose centroid would move at twice the frequency) is tracked by image shift.

numpy and scipy only; a 25-s 550×310 phone clip takes about 2 s.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from physinfer.errors import NothingMoves, UserInputError
from physinfer.types import Clip

#: Long side, in pixels, that frames are reduced to before tracking.
TRACK_SIDE = 160
#: Frames sampled for the background median (all, when fewer).
BACKGROUND_FRAMES = 240
#: A pixel that is foreground in more than this share of frames changes in place: dropped.
MAX_OCCUPANCY = 0.6
#: Foreground threshold: this many robust spreads above the median difference...
THRESHOLD_SPREADS = 6.0
#: ...and at least this much (sum over RGB, of 765).
MIN_THRESHOLD = 24.0
#: A path seen by image shift at this ratio of the centroid's frequency (about half) means the
#: centroid saw two crescents (a swing smaller than the subject): the shift path is used.
DOUBLED = (0.4, 0.6)
#: Share of frames that may lack a foreground (filled by interpolation) before tracking fails.
MAX_LOST = 0.25
#: A region of the motion-energy map counts as a mover when it holds this share of all motion.
MOVER_SHARE = 0.1
#: Regions are the connected parts of the energy map above this share of its peak.
REGION_LEVEL = 0.05
#: Fewest of the moving pixels' weight near their centroid for one subject (see gathered_share).
MIN_GATHERED = 0.3


@dataclass(frozen=True)
class MotionTrack:
    """The path of the moving subject.

    Attributes:
        xy: ``(T, 2)`` centroid per frame in the clip's pixels (x right, y down).
        fps: Frame rate in Hz.
        area: ``(T,)`` foreground pixels per frame (in the reduced frames).
        lost: Frames without foreground (their centroid interpolated).
        frame_size: ``(height, width)`` of the clip.
        method: ``"centroid"`` (the foreground's centroid) or ``"shift"`` (first-order image
            shift, for a swing smaller than the subject; its size and curvature are not the
            path's).
    """

    xy: np.ndarray
    fps: float
    area: np.ndarray
    lost: int
    frame_size: tuple[int, int]
    method: str = "centroid"

    @property
    def duration_s(self) -> float:
        """Seconds the track spans."""
        return len(self.xy) / self.fps

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The track in its principal axes: ``(u, v, direction)``.

        ``u`` ``(T,)`` runs along the direction of largest motion (a pendulum's swing), ``v``
        across it, both about their means; ``direction`` is the unit vector of ``u`` in image
        coordinates. The sign of ``u`` is chosen so that it starts non-negative.
        """
        centred = self.xy - self.xy.mean(axis=0)
        _, _, vt = np.linalg.svd(centred, full_matrices=False)
        direction = vt[0] if vt[0][np.argmax(np.abs(vt[0]))] > 0 else -vt[0]
        across = np.array([-direction[1], direction[0]])
        return centred @ direction, centred @ across, direction


def reduced_frames(frames: np.ndarray, side: int = TRACK_SIDE) -> tuple[np.ndarray, int]:
    """``(T, H, W, 3)`` uint8 → ``(T, h, w, 3)`` float32 by striding, and the stride."""
    height, width = frames.shape[1:3]
    stride = max(1, int(np.ceil(max(height, width) / side)))
    return frames[:, ::stride, ::stride].astype(np.float32), stride


def foreground(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Foreground masks of reduced frames and each pixel's difference from the background.

    Args:
        frames: ``(T, h, w, C)`` float32.

    Returns:
        ``(mask, difference, threshold)``: ``(T, h, w)`` bool, ``(T, h, w)`` float32 (sum of
        absolute channel differences) and the threshold used.
    """
    step = max(1, len(frames) // BACKGROUND_FRAMES)
    background = np.median(frames[::step], axis=0)
    difference = np.abs(frames - background).sum(axis=-1)
    sample = difference[::step].ravel()
    centre = float(np.median(sample))
    spread = 1.4826 * float(np.median(np.abs(sample - centre)))
    threshold = max(centre + THRESHOLD_SPREADS * spread, MIN_THRESHOLD)
    mask = difference > threshold
    mask &= mask.mean(axis=0) <= MAX_OCCUPANCY
    return mask, difference, threshold


def peak_frequency(signal: np.ndarray, fps: float) -> float:
    """The strongest frequency (Hz) of a signal (Hann window, zero-padded FFT)."""
    n = len(signal)
    power = np.abs(np.fft.rfft((signal - signal.mean()) * np.hanning(n), max(4096, 8 * n))) ** 2
    return float(np.argmax(power[1:]) + 1) * fps / max(4096, 8 * n)


def principal(path: np.ndarray) -> np.ndarray:
    """A ``(T, 2)`` path along its direction of largest motion, ``(T,)``."""
    centred = path - path.mean(axis=0)
    return centred @ np.linalg.svd(centred, full_matrices=False)[2][0]


def small_motion_path(frames: np.ndarray, region: np.ndarray) -> np.ndarray:
    """Displacement ``(T, 2)`` (x, y, reduced pixels) of what moves in ``region``, for motion
    smaller than the subject: each frame differs from the mean image by about
    ``-d · ∇mean`` (a first-order image shift), solved for ``d`` by least squares."""
    from scipy import ndimage

    grey = frames.mean(axis=-1)
    mean = ndimage.gaussian_filter(grey.mean(axis=0), 1.0)
    gy, gx = np.gradient(mean)
    g = np.stack([gx[region], gy[region]], axis=1)  # (P, 2)
    residual = ndimage.gaussian_filter(grey, (0, 1.0, 1.0))[:, region] - mean[region]  # (T, P)
    return -np.linalg.lstsq(g, residual.T, rcond=None)[0].T


def moving_regions(clip: Clip, *, side: int = TRACK_SIDE) -> list[dict[str, object]]:
    """The separate regions that move in ``clip``, largest share of motion first.

    Returns:
        One record per region holding at least :data:`MOVER_SHARE` of the motion energy:
        ``share`` and ``box`` ``(x, y, w, h)`` in the clip's pixels.
    """
    from scipy import ndimage

    frames, stride = reduced_frames(clip.frames, side)
    mask, difference, _ = foreground(frames)
    energy = np.where(mask, difference, 0.0).sum(axis=0)
    if energy.max() <= 0:
        return []
    strong = ndimage.binary_closing(energy > REGION_LEVEL * energy.max(), iterations=2)
    labels, n = ndimage.label(strong, structure=np.ones((3, 3)))
    total = float(energy.sum())
    regions = []
    for index, found in enumerate(ndimage.find_objects(labels), start=1):
        share = float(energy[labels == index].sum()) / total
        if share >= MOVER_SHARE:
            ys, xs = found
            box = (xs.start * stride, ys.start * stride, (xs.stop - xs.start) * stride, (ys.stop - ys.start) * stride)
            regions.append({"share": round(share, 3), "box": box})
    return sorted(regions, key=lambda r: -r["share"])


def gathered_share(clip: Clip, *, side: int = TRACK_SIDE) -> float:
    """Median share, over frames, of the moving pixels' weight within a tenth of the frame's
    diagonal of their centroid. One subject (a ball; a bob with its string) keeps it high:
    0.47-1.0 over 16 randomised pendulum renders, 0.998 for a phone video of a ball; two
    things moving apart put the centroid between them (0.17 for a film whose animated dials
    flicker beside its pendulum)."""
    frames, _ = reduced_frames(clip.frames, side)
    mask, difference, _ = foreground(frames)
    weight = np.where(mask, difference, 0.0)
    mass = weight.sum(axis=(1, 2))
    found = mass > 0
    if not found.any():
        return 1.0
    ys, xs = np.mgrid[0 : frames.shape[1], 0 : frames.shape[2]]
    safe = np.maximum(mass, 1e-9)[:, None, None]
    cx = (weight * xs).sum(axis=(1, 2), keepdims=True) / safe
    cy = (weight * ys).sum(axis=(1, 2), keepdims=True) / safe
    reach = 0.1 * float(np.hypot(*frames.shape[1:3]))
    near = ((xs - cx) ** 2 + (ys - cy) ** 2) <= reach**2
    return float(np.median(((weight * near).sum(axis=(1, 2)) / safe[:, 0, 0])[found]))


def check_one_mover(clip: Clip, *, roi: tuple[float, float, float, float] | None = None) -> None:
    """Refuse a clip in which more than one thing moves (the track would mix them): separate
    moving regions, or moving pixels that lie apart (:func:`gathered_share` below
    :data:`MIN_GATHERED`).

    ``roi``: the region ``(x, y, w, h)`` of the user's video that ``clip`` was cropped to; the
    boxes are then said in the video's pixels and the advice is a smaller region.

    Raises:
        UserInputError: naming each moving region's box and how to pick one (``--roi``).
    """
    where = "this video" if roi is None else f"--roi {','.join(f'{v:g}' for v in roi)}"
    advice = (
        "give the subject's region with --roi x,y,w,h (in the video's pixels)"
        if roi is None
        else "give a --roi x,y,w,h around the subject alone (in the video's pixels)"
    )
    share = gathered_share(clip)
    if share < MIN_GATHERED:
        raise UserInputError(
            f"more than one thing moves in {where}: its moving pixels lie apart (only {100 * share:.0f} % "
            f"near their centre); {advice}"
        )
    regions = moving_regions(clip)
    if len(regions) > 1:
        x0, y0 = (0, 0) if roi is None else (int(roi[0]), int(roi[1]))
        boxes = "; ".join(
            f"x,y,w,h {_box_text(r['box'], x0, y0)} ({100 * r['share']:.0f} % of the motion)" for r in regions
        )
        raise UserInputError(f"{len(regions)} things move in {where} ({boxes}): {advice}")


def _box_text(box: Sequence[float], x0: int, y0: int) -> str:
    """``x,y,w,h`` of a region's box moved by ``(x0, y0)`` (a crop's corner in the video)."""
    x, y, w, h = (int(v) for v in box)
    return f"{x + x0},{y + y0},{w},{h}"


def half_swings(u: np.ndarray, fps: float) -> tuple[int, float | None]:
    """Crossings of a track's centre line, and the mean time between them (half a period).

    Crossings closer than a tenth of a second are jitter, counted once.
    """
    sign = np.sign(u - np.median(u))
    sign[sign == 0] = 1
    crossings = np.flatnonzero(np.diff(sign) != 0) / fps
    kept = [t for i, t in enumerate(crossings) if i == 0 or t - crossings[i - 1] > 0.1]
    if len(kept) < 2:
        return len(kept), None
    return len(kept), float(np.mean(np.diff(kept)))


def track_motion(clip: Clip, *, side: int = TRACK_SIDE, allow_shift: bool = False) -> MotionTrack:
    """The centroid path of what moves in ``clip``.

    ``allow_shift``: where the centroid's frequency is twice the image shift's (a swing
    smaller than the subject), return the shift path instead. The choice is a jump, so an
    embedding (which must vary smoothly with θ) leaves it off; a one-off reading of the
    period (a phenomenon's ``video_estimate``) turns it on.

    Raises:
        NothingMoves: nothing moves, or the subject is lost in more than a quarter of the
            frames (a :class:`UserInputError`: said in one line about a user's video).
    """
    frames, stride = reduced_frames(clip.frames, side)
    mask, difference, _ = foreground(frames)
    weight = np.where(mask, difference, 0.0)
    mass = weight.sum(axis=(1, 2))
    found = mass > 0
    if found.sum() < 2:
        raise NothingMoves("nothing moves in this video: no frame differs from the background")
    lost = int((~found).sum())
    if lost > MAX_LOST * len(frames):
        raise NothingMoves(
            f"the moving subject is lost in {lost} of {len(frames)} frames: give a clip in which "
            "it stays in view (trim it with 'physinfer prepare --start/--duration')"
        )
    ys, xs = np.mgrid[0 : frames.shape[1], 0 : frames.shape[2]]
    safe = np.where(found, mass, 1.0)
    cx = (weight * xs).sum(axis=(1, 2)) / safe
    cy = (weight * ys).sum(axis=(1, 2)) / safe
    t = np.arange(len(frames))
    if lost:
        cx = np.interp(t, t[found], cx[found])
        cy = np.interp(t, t[found], cy[found])
    method = "centroid"
    if allow_shift:
        # A subject that swings less than its own size covers the middle of its path all the
        # time: the median background holds it, the foreground is two crescents, and their
        # centroid moves at twice the frequency. The first-order image shift sees the true path.
        from scipy import ndimage

        shift = small_motion_path(frames, ndimage.binary_dilation(mask.any(axis=0), iterations=3))
        centroid_f = peak_frequency(principal(np.stack([cx, cy], axis=1)), clip.fps)
        if centroid_f > 0 and DOUBLED[0] <= peak_frequency(principal(shift), clip.fps) / centroid_f <= DOUBLED[1]:
            cx, cy, method = cx.mean() + shift[:, 0], cy.mean() + shift[:, 1], "shift"
    xy = (np.stack([cx, cy], axis=1) + 0.5) * stride - 0.5
    return MotionTrack(xy, float(clip.fps), mask.sum(axis=(1, 2)), lost, tuple(clip.frames.shape[1:3]), method)
