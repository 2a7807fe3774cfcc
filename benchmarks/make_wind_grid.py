"""Build the documentation's still grid of one flag at several wind speeds from videos.

Each row is one video (one wind speed), each column a still at the same time in every
video; rows are labelled. With ``--simulate`` the videos are first made by the command
the docs show::

    physinfer simulate --plugin flag --set wind_speed=W --out flag_W.mp4

Usage (the docs' figure, docs/img/flag_wind_grid.png)::

    PYOPENGL_PLATFORM=egl python benchmarks/make_wind_grid.py --simulate --speeds 0,3,6,9 \\
        --workdir /tmp/wind_grid --out docs/img/flag_wind_grid.png

or from existing videos (label each with its speed)::

    python benchmarks/make_wind_grid.py --videos w0.mp4 w3.mp4 w6.mp4 w9.mp4 --labels 0,3,6,9

Prints one JSON object (output path, videos, still times) on stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command-line options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--videos", nargs="*", type=Path, default=[], help="one video per row")
    parser.add_argument("--labels", default=None, help="comma-separated wind speeds (m/s), one per video")
    parser.add_argument("--simulate", action="store_true", help="make the videos with `physinfer simulate`")
    parser.add_argument("--speeds", default="0,3,6,9", help="wind speeds for --simulate (default: 0,3,6,9)")
    parser.add_argument("--workdir", type=Path, default=Path("wind_grid_videos"), help="where --simulate writes")
    parser.add_argument("--times", default="0.4,0.8,1.2,1.6", help="still times in seconds (default: 0.4,...,1.6)")
    parser.add_argument("--tile", type=int, default=160, help="still size in pixels (default: 160)")
    parser.add_argument("--out", type=Path, default=Path("docs/img/flag_wind_grid.png"))
    return parser.parse_args(argv)


def simulate_videos(speeds: Sequence[float], workdir: Path) -> list[Path]:
    """Run ``physinfer simulate --plugin flag --set wind_speed=W --out ...`` for each speed."""
    workdir.mkdir(parents=True, exist_ok=True)
    physinfer = Path(sys.executable).with_name("physinfer")
    command = [str(physinfer)] if physinfer.exists() else [sys.executable, "-m", "physinfer.cli"]
    videos = []
    for speed in speeds:
        out = workdir / f"flag_wind_{speed:g}.mp4"
        args = [*command, "simulate", "--plugin", "flag", "--set", f"wind_speed={speed:g}", "--out", str(out),
                "--overwrite"]  # its own videos, made again on each run
        print("running:", " ".join(args), file=sys.stderr)
        subprocess.run(args, check=True, stdout=sys.stderr)
        videos.append(out)
    return videos


def stills(path: Path, times: Sequence[float], tile: int) -> list[np.ndarray]:
    """Frames of ``path`` nearest to ``times``, centre-cropped to ``(tile, tile, 3)``."""
    from physinfer.errors import UserInputError
    from physinfer.video import center_crop_resize, read_video

    clip = read_video(path)
    picked = []
    for t in times:
        index = int(round(t * clip.fps))
        if index >= clip.n_frames:
            raise UserInputError(f"{path} lasts {clip.duration:.2f} s: no still at {t:g} s; choose earlier --times")
        picked.append(clip.frames[index])
    return list(center_crop_resize(np.stack(picked), tile))


def grid_image(rows: Sequence[Sequence[np.ndarray]], labels: Sequence[str], times: Sequence[float],
               tile: int) -> np.ndarray:
    """Lay stills out in a labelled grid; returns ``(H, W, 3)`` uint8."""
    from PIL import Image, ImageDraw

    gap, label_width, header = 4, 90, 24
    n_rows, n_cols = len(rows), len(rows[0])
    width = label_width + n_cols * (tile + gap)
    height = header + n_rows * (tile + gap)
    canvas = Image.new("RGB", (width, height), "white")
    draw = ImageDraw.Draw(canvas)
    for c, t in enumerate(times):
        draw.text((label_width + c * (tile + gap) + tile // 2 - 14, 6), f"t = {t:g} s", fill="black")
    for r, (row, label) in enumerate(zip(rows, labels, strict=True)):
        top = header + r * (tile + gap)
        draw.text((8, top + tile // 2 - 6), label, fill="black")
        for c, still in enumerate(row):
            canvas.paste(Image.fromarray(still), (label_width + c * (tile + gap), top))
    return np.asarray(canvas)


def main(argv: list[str] | None = None) -> None:
    """Build the grid and print one JSON object."""
    from PIL import Image

    from physinfer.io import atomic_path

    args = parse_args(argv)
    times = [float(t) for t in args.times.split(",")]
    if args.simulate:
        speeds = [float(s) for s in args.speeds.split(",")]
        videos, labels = simulate_videos(speeds, args.workdir), [f"{s:g} m/s" for s in speeds]
    else:
        videos = list(args.videos)
        if not videos:
            raise SystemExit("give --videos (one per wind speed) or --simulate")
        raw = args.labels.split(",") if args.labels else [p.stem for p in videos]
        if len(raw) != len(videos):
            raise SystemExit(f"{len(raw)} labels for {len(videos)} videos")
        labels = [f"{x} m/s" if x.replace(".", "", 1).isdigit() else x for x in raw]
    rows = [stills(v, times, args.tile) for v in videos]
    image = grid_image(rows, labels, times, args.tile)
    with atomic_path(args.out, suffix=".png") as tmp:
        Image.fromarray(image).save(tmp, format="PNG")
    print(json.dumps({"out": str(args.out), "videos": [str(v) for v in videos], "labels": labels, "times_s": times,
                      "size": list(image.shape[:2])}))


if __name__ == "__main__":
    main()
