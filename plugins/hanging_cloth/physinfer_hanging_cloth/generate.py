"""A synthetic dataset in exactly the Bouman format, made with the hanging-cloth simulator.

``n_fabrics`` fabrics (30 by default) get a stiffness and an area weight drawn
log-uniformly over the real fabrics' ranges (units.py) and two measurements each, as
Bouman et al. measured them (stiffness in two orthogonal directions, area weight twice);
the simulator uses their means, which is what the loader computes. Each fabric gets its
own print and colours and is filmed at the three fan levels W1–W3 with its own gusts.
The table goes to ``ground_truth.csv`` (oz/yd², lbf·in²), the videos to
``videos/<fabric>_W<k>.mp4``, the settings to ``synthetic.json``. Every file is written
atomically and existing videos are kept, so running again on the same directory with the
same settings resumes; other settings are refused.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from physinfer.errors import UserInputError
from physinfer.io import atomic_write_json, atomic_write_text
from physinfer.video import write_video
from physinfer_hanging_cloth.data import VIDEO_DIR
from physinfer_hanging_cloth.fan import FAN_LEVELS
from physinfer_hanging_cloth.units import (
    REAL_AREA_WEIGHT_OZ_YD2,
    REAL_STIFFNESS_LBF_IN2,
    oz_yd2_to_kg_m2,
    stiffness_to_multiplier,
)

SETTINGS_FILE = "synthetic.json"
TABLE_FILE = "ground_truth.csv"
TABLE_HEADER = [
    "fabric", "area_weight_1 [oz/yd^2]", "area_weight_2 [oz/yd^2]", "stiffness_1 [lbf*in^2]", "stiffness_2 [lbf*in^2]",
]


@dataclass(frozen=True)
class SyntheticSettings:
    """What a synthetic dataset is made of; the same settings make the same data.

    Attributes:
        n_fabrics: Fabrics (30 in Bouman et al.).
        n_frames: Recorded frames per video (after a 1 s warm-up).
        image_size: Side of the square videos in pixels.
        seed: Seed of the fabrics, their looks and the fan's gusts.
        anisotropy: Largest log-ratio between a fabric's stiffness measurement and the
            mean (orthogonal directions differ by up to ``exp(2 · anisotropy)``).
        area_weight_noise: Relative spread of the two area-weight measurements.
    """

    n_fabrics: int = 30
    n_frames: int = 60
    image_size: int = 224
    seed: int = 0
    anisotropy: float = 0.25
    area_weight_noise: float = 0.02

    def validate(self) -> None:
        """Raise :class:`UserInputError` naming the first bad setting."""
        if not 3 <= self.n_fabrics <= 999:
            raise UserInputError(f"the number of fabrics must be in [3, 999], got {self.n_fabrics}")
        if not 2 <= self.n_frames <= 10_000:
            raise UserInputError(f"frames per video must be in [2, 10000], got {self.n_frames}")
        if not 32 <= self.image_size <= 1024:
            raise UserInputError(f"the video size must be 32 to 1024 pixels, got {self.image_size}")
        if not 0 <= self.anisotropy <= 1 or not 0 <= self.area_weight_noise <= 0.2:
            raise UserInputError("anisotropy must be in [0, 1] and area_weight_noise in [0, 0.2]")


@dataclass(frozen=True)
class SyntheticFabric:
    """One synthetic fabric: its two measurements of each quantity and its look.

    Attributes:
        name: ``fabric01`` …
        area_weight: Two measurements in oz/yd².
        stiffness: Two measurements in lbf·in².
        look: ζ keys of its print and colours.
    """

    name: str
    area_weight: tuple[float, float]
    stiffness: tuple[float, float]
    look: dict

    def params(self) -> dict[str, float]:
        """θ of the simulator from the measurements' means (as the loader averages them)."""
        return {
            "bending_multiplier": stiffness_to_multiplier(float(np.mean(self.stiffness))),
            "area_weight": oz_yd2_to_kg_m2(float(np.mean(self.area_weight))),
        }


def sample_fabrics(settings: SyntheticSettings) -> list[SyntheticFabric]:
    """Draw the fabrics (log-uniform over the real ranges) and their looks, deterministically."""
    from physinfer_hanging_cloth.render import sample_fabric_look

    rng = np.random.default_rng([settings.seed, 2013])
    fabrics = []
    width = max(2, len(str(settings.n_fabrics)))
    for index in range(settings.n_fabrics):
        stiffness = math.exp(rng.uniform(*np.log(REAL_STIFFNESS_LBF_IN2)))
        area_weight = math.exp(rng.uniform(*np.log(REAL_AREA_WEIGHT_OZ_YD2)))
        tilt = rng.uniform(-settings.anisotropy, settings.anisotropy)
        noise = rng.uniform(-settings.area_weight_noise, settings.area_weight_noise)
        fabrics.append(
            SyntheticFabric(
                name=f"fabric{index + 1:0{width}d}",
                area_weight=(round(area_weight * (1 + noise), 4), round(area_weight * (1 - noise), 4)),
                stiffness=(round(stiffness * math.exp(tilt), 6), round(stiffness * math.exp(-tilt), 6)),
                look=sample_fabric_look(rng),
            )
        )
    return fabrics


def table_text(fabrics: list[SyntheticFabric]) -> str:
    """The ground-truth CSV of ``fabrics`` (header with units, one row per fabric)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(TABLE_HEADER)
    for f in fabrics:
        writer.writerow([f.name, *f.area_weight, *f.stiffness])
    return buffer.getvalue()


def video_seed(settings: SyntheticSettings, fabric_index: int, level_index: int) -> int:
    """Seed of one video's initial perturbation and gusts."""
    return settings.seed * 100_000 + fabric_index * 10 + level_index


def _check_settings_file(out: Path, settings: SyntheticSettings) -> None:
    path = out / SETTINGS_FILE
    if not path.is_file():
        if (out / VIDEO_DIR).exists() or (out / TABLE_FILE).exists():
            raise UserInputError(f"{out} already holds data not made by this generator; choose an empty --out")
        return
    stored = json.loads(path.read_text())
    if stored.get("settings") != asdict(settings):
        raise UserInputError(
            f"{out} holds a synthetic dataset made with other settings ({stored.get('settings')}); "
            "choose another --out or repeat those settings to resume"
        )


def generate_dataset(
    out: str | Path,
    settings: SyntheticSettings,
    *,
    on_video: Callable[[int, int], None] | None = None,
) -> dict:
    """Write (or complete) a synthetic Bouman-format dataset in ``out``.

    Args:
        out: Dataset directory (created; resumed when it holds the same settings).
        settings: What to generate.
        on_video: Progress callback ``(done, total)`` after each fabric.

    Returns:
        A summary: directory, fabrics, videos written and kept, seconds per video.

    Raises:
        UserInputError: bad settings, or ``out`` holding other data.
        SimulationFailed: when a fabric's simulation blows up.
    """
    import time

    from physinfer_hanging_cloth.render import HangingClothRenderer
    from physinfer_hanging_cloth.simulator import make_simulator

    settings.validate()
    out = Path(out)
    _check_settings_file(out, settings)
    fabrics = sample_fabrics(settings)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(
        out / SETTINGS_FILE,
        {
            "generator": "physinfer_hanging_cloth.generate",
            "settings": asdict(settings),
            "fabrics": [{"name": f.name, **f.params(), "look": f.look} for f in fabrics],
        },
    )
    atomic_write_text(out / TABLE_FILE, table_text(fabrics))
    simulator = make_simulator((), n_frames=settings.n_frames)
    renderer = HangingClothRenderer()
    written = kept = 0
    started = time.perf_counter()
    try:
        for index, fabric in enumerate(fabrics):
            paths = [out / VIDEO_DIR / f"{fabric.name}_{level}.mp4" for level in FAN_LEVELS]
            todo = [k for k, p in enumerate(paths) if not p.is_file()]
            kept += len(paths) - len(todo)
            if todo:
                trajectories = simulator.simulate_videos(
                    [fabric.params()] * len(todo),
                    seeds=[video_seed(settings, index, k) for k in todo],
                    fan_levels=[FAN_LEVELS[k] for k in todo],
                )
                zeta = {**renderer.default_render_params, **fabric.look, "image_size": settings.image_size}
                for k, trajectory in zip(todo, trajectories, strict=True):
                    write_video(paths[k], renderer.render(trajectory, zeta))
                    written += 1
            if on_video is not None:
                on_video(index + 1, len(fabrics))
    finally:
        renderer.close()
    elapsed = time.perf_counter() - started
    return {
        "out": str(out),
        "n_fabrics": len(fabrics),
        "n_videos": len(fabrics) * len(FAN_LEVELS),
        "written": written,
        "kept": kept,
        "seconds_per_video": elapsed / written if written else None,
    }
