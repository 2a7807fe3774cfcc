"""The flag renderer's ζ: :class:`FlagRenderParams`, every field a key of the render
parameters, and its checks.

Below the renderer (:mod:`physinfer_flag.render`, which re-exports it) and the flag's scene
(:mod:`physinfer_flag.flag_scene`, whose camera reads it).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from physinfer.errors import UserInputError
from physinfer_flag.backgrounds import BACKGROUND_NAMES
from physinfer_flag.sheet_render import SheetViewParams, check_view
from physinfer_flag.textures import FLAG_NAMES

MAX_WIND_CAMERA_ANGLE_DEG = 15.0
"""The paper's limit on the angle between the wind direction and the camera axis."""


@dataclass(frozen=True)
class FlagRenderParams(SheetViewParams):
    """Render parameters ζ of :class:`~physinfer_flag.render.FlagRenderer`; every field is a key of the ζ dict.

    Attributes:
        image_size: Output size in pixels: one int for a square image or ``(H, W)``.
        camera_distance: Distance in metres from the camera to the look-at target, or
            None to frame the flag automatically: a square of 1.36 fly lengths from
            0.18 lengths above the hoist top down to 1.18 below, so the flag stays in
            view flying straight or drooping in a light wind.
        framing: Multiplier of the automatic distance (> 1 shows more surroundings);
            ignored when ``camera_distance`` is given.
        camera_azimuth_deg: Horizontal angle of the camera around the look-at target;
            0 looks at the flag face-on along +y (wind blowing left to right), positive
            values move the camera downwind. Must satisfy ``|azimuth| <= 15``.
        camera_elevation_deg: Angle of the camera above the target's horizontal plane;
            negative looks up at the flag, as from the ground. In ``[-45, 45]``.
        fov_deg: Vertical field of view in degrees, in ``(5, 120)``.
        light_direction: ``(3,)`` direction the sunlight travels in world coordinates
            (the default comes from above, behind the camera and from the left).
        light_intensity: Directional light intensity (pyrender units, ``>= 0``).
        ambient_intensity: Ambient light in ``[0, 1]``, keeps shaded folds from going black.
        texture: Flag design, one of :data:`physinfer_flag.textures.FLAG_NAMES`.
        background: A procedural background name
            (:data:`physinfer_flag.backgrounds.BACKGROUND_NAMES`) or an image path.
        pole: Draw the flag pole.
    """

    settings_owner: ClassVar[str] = "flag"

    image_size: int | tuple[int, int] = 224
    camera_distance: float | None = None
    framing: float = 1.0
    camera_azimuth_deg: float = 0.0
    camera_elevation_deg: float = -5.0
    fov_deg: float = 40.0
    light_direction: tuple[float, float, float] = (0.35, 0.8, -0.5)
    light_intensity: float = 2.5
    ambient_intensity: float = 0.3
    texture: str = "netherlands"
    background: str = "sky_cloudy"
    pole: bool = True

    def validate(self) -> None:
        """Check every value; raises :class:`UserInputError` naming the offending key."""
        check_view(self)
        if self.camera_distance is not None and not (0 < self.camera_distance < 1e4):
            raise UserInputError(f"camera_distance={self.camera_distance}: give a positive distance in metres or None")
        if abs(self.camera_azimuth_deg) > MAX_WIND_CAMERA_ANGLE_DEG:
            raise UserInputError(
                f"camera_azimuth_deg={self.camera_azimuth_deg:g}: the angle between the wind direction "
                f"and the camera axis must be at most {MAX_WIND_CAMERA_ANGLE_DEG:g}° (as in the paper); "
                f"choose camera_azimuth_deg in [-{MAX_WIND_CAMERA_ANGLE_DEG:g}, {MAX_WIND_CAMERA_ANGLE_DEG:g}]"
            )
        if self.texture.lower() not in FLAG_NAMES:
            raise UserInputError(f"texture={self.texture!r} is unknown; choose one of: {', '.join(FLAG_NAMES)}")
        if self.background not in BACKGROUND_NAMES and not Path(self.background).expanduser().is_file():
            raise UserInputError(
                f"background={self.background!r} is neither a procedural background "
                f"({', '.join(BACKGROUND_NAMES)}) nor an existing image file"
            )
