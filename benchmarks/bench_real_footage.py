"""physinfer on real footage: the pendulum's length from real videos, against the period.

For each clip of ``../shared/realvideo`` (its README gives the ground truth), runs
``physinfer refine --plugin pendulum`` as a user would (defaults; ``--roi`` where a clip
needs one) and prints one JSON object: per clip the length found, the length the README's
period gives (``g T² / 4π²``), the relative error, the adequacy verdict, the trials and the
wall time; and the same clips refined with the worked example's lab world
(``--plugin pendulum_lab``, ``--lab``), which cannot make them and must say so.

Usage::

    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_real_footage.py --out runs/bench_real [--lab]

Clips that are absent are reported as skipped, with the path looked for.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "realvideo"
G = 9.81
#: case → (clip, period in s from the README, extra refine options); the classroom film is run
#: whole (refused: its dials move too) and in the pendulum's region, as docs/real-footage.md shows.
CLIPS = {
    "ball_on_string.mp4": ("ball_on_string.mp4", 1.02, []),
    "classroom_1m.mp4": ("classroom_1m.mp4", 2.006, []),
    "classroom_1m.mp4 --roi": ("classroom_1m.mp4", 2.006, ["--roi", "0,120,320,120"]),
}


def refine(plugin: str, video: Path, out: Path, options: list[str]) -> dict:
    """Run the CLI; the result.json, or the error line it ended with."""
    binary = Path(sys.executable).parent / "physinfer"
    start = time.perf_counter()
    proc = subprocess.run(
        [str(binary), "refine", "--plugin", plugin, "--target", str(video), "--out", str(out), "--overwrite", *options],
        capture_output=True, text=True,
    )  # fmt: skip
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        return {"error": proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else f"exit {proc.returncode}",
                "wall_time_s": round(wall, 1)}  # fmt: skip
    result = json.loads((out / "result.json").read_text())
    return {
        "length_m": result["best_params"].get("length"),
        "best_params": result["best_params"],
        "adequacy": result.get("adequacy"),
        "n_trials": result["n_trials"],
        "wall_time_s": round(wall, 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("runs/bench_real"))
    parser.add_argument("--lab", action="store_true", help="also refine each clip with the lab world (pendulum_lab)")
    parser.add_argument("--clips", nargs="*", default=list(CLIPS), help="cases (clip names in ../shared/realvideo, 'classroom_1m.mp4 --roi')")
    args = parser.parse_args()
    rows = {}
    for name in args.clips:
        clip, period, options = CLIPS[name]
        video = REAL / clip
        if not video.exists():
            rows[name] = {"skipped": f"{video} is absent"}
            continue
        run_name = Path(clip).stem + ("-roi" if "--roi" in options else "")
        truth = G * period**2 / (4 * math.pi**2)
        row = {"truth_length_m": round(truth, 4), **refine("pendulum", video, args.out / run_name, options)}
        if row.get("length_m") is not None:
            row["relative_error"] = round(row["length_m"] / truth - 1, 4)
        if args.lab:
            row["lab_world"] = refine("pendulum_lab", video, args.out / f"{run_name}-lab", [])
        rows[name] = row
    print(json.dumps({"clips": rows}, indent=2))


if __name__ == "__main__":
    main()
