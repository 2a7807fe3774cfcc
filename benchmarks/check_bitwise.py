"""Bit-for-bit fingerprint of the cloth plugins and the dataset engine, to prove a refactor changed nothing.

Records SHA-256 hashes of:

* ``traj/*``: flag trajectories (vertex positions) for several (θ, seed) pairs, with
  effects switched in (gusts, shear, yaw, inclination) and with both pinnings of the
  scene (``--scene-set pinning=corners``), from ``simulate``;
* ``batch/*``: ``simulate_batch`` of 3 flags (and ``batch_equals_single``: whether each
  batched flag equals its single run bitwise — true since each flag of a batch reads only its
  own wind table; the second batch mixes a flag without gusts with flags with gusts);
* ``render/*``: rendered frames of 2 flag clips at 2 ζ (the default and a sampled one) and
  of one hanging-cloth clip (it reuses the flag's sheet-rendering helpers);
* ``dataset/*``: a tiny flag dataset generated through the CLI (manifest, shards and
  trajectory arrays).

Usage::

    python benchmarks/check_bitwise.py --save /tmp/before.json      # before the change
    python benchmarks/check_bitwise.py --compare /tmp/before.json   # after: exit 1 on any difference
    python benchmarks/check_bitwise.py --only traj,batch            # a subset of the sections

Prints one JSON object (the hashes, and with ``--compare`` the differing keys) on stdout.
Hashes are of float arrays produced by compiled code: compare on the same machine (and
numba/LLVM version) only.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

SECTIONS = ("traj", "batch", "render", "dataset")
CLIP_S = 1.0  # recorded seconds of the short clips (the physics is the same at any length)

GUSTS = {"gust_intensity": 0.3, "gust_timescale": 1.0}
# (name, effect names, scene settings, θ, seed)
CASES: tuple[tuple[str, tuple[str, ...], dict[str, Any] | None, dict[str, float], int], ...] = (
    ("default", (), None, {"wind_speed": 5.0}, 0),
    ("stiff_heavy", (), None, {"wind_speed": 8.0, "area_weight": 0.16, "bend_0deg_c00": 3.0,
                               "bend_45deg_c10": 0.3, "bend_90deg_c20": 6.0}, 7),
    ("gusts_shear", ("wind_gusts", "wind_shear"), None, {"wind_speed": 6.0, **GUSTS, "shear_exponent": 0.3}, 3),
    ("yaw_inclination", ("wind_yaw", "wind_inclination"), None,
     {"wind_speed": 7.0, "wind_yaw_deg": 20.0, "wind_inclination_deg": -10.0}, 4),
    ("corners", (), {"pinning": "corners"}, {"wind_speed": 7.0, "area_weight": 0.12}, 1),
    ("corners_gusts_big", ("wind_gusts",), {"pinning": "corners", "flag_length": 1.2, "flag_height": 0.8},
     {"wind_speed": 4.0, **GUSTS}, 2),
)


def digest(array: np.ndarray) -> str:
    """SHA-256 of an array's dtype, shape and bytes."""
    a = np.ascontiguousarray(array)
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes())
    return h.hexdigest()


def flag_simulator(effects: tuple[str, ...], scene: dict[str, Any] | None, *, full: bool = False) -> Any:
    """The flag simulator as the CLI builds it: named effects, ``--scene-set`` settings."""
    from physinfer.scene import resolve_scene
    from physinfer_flag import effects as flag_effects
    from physinfer_flag.phenomenon import make_phenomenon, make_simulator

    by_name = {e.name: e for e in (flag_effects.WindGusts(), flag_effects.WindShear(), flag_effects.WindYaw(),
                                   flag_effects.WindInclination())}
    resolved = resolve_scene(make_phenomenon(), scene)
    return make_simulator([by_name[n] for n in effects], duration_s=None if full else CLIP_S, scene=resolved)


def first_frames(trajectory: Any, n: int) -> Any:
    """The trajectory cut to its first ``n`` frames (rendering is the slow part)."""
    return replace(trajectory, vertices=trajectory.vertices[:n])


def trajectories() -> dict[str, Any]:
    """``simulate`` of every case (the first at the default 60 frames)."""
    out: dict[str, Any] = {}
    for index, (name, effects, scene, theta, seed) in enumerate(CASES):
        sim = flag_simulator(effects, scene, full=index == 0)
        out[f"traj/{name}"] = digest(sim.simulate(theta, seed=seed).vertices)
    return out


def batches() -> dict[str, Any]:
    """``simulate_batch`` of 3 on two simulators, and whether it equals single runs bitwise."""
    out: dict[str, Any] = {}
    same = True
    for name, effects, scene, thetas, seeds in (
        ("plain", (), None, [{"wind_speed": 3.0}, {"wind_speed": 9.0, "area_weight": 0.15}, {"wind_speed": 6.0}],
         [0, 1, 5]),
        ("corners_gusts", ("wind_gusts",), {"pinning": "corners"},
         [{"wind_speed": 5.0, **GUSTS}, {"wind_speed": 7.0}, {"wind_speed": 2.0, "gust_intensity": 0.1}], [3, 3, 9]),
    ):
        sim = flag_simulator(effects, scene)
        batch = sim.simulate_batch(thetas, seeds=seeds)
        for k, traj in enumerate(batch):
            out[f"batch/{name}/{k}"] = digest(traj.vertices)
            same &= bool(np.array_equal(traj.vertices, sim.simulate(thetas[k], seed=seeds[k]).vertices))
    out["batch/batch_equals_single"] = same
    return out


def renders() -> dict[str, Any]:
    """Two flag clips at the default and a sampled ζ, and one hanging-cloth clip."""
    from physinfer_flag.phenomenon import make_renderer
    from physinfer_hanging_cloth.phenomenon import make_renderer as hanging_renderer
    from physinfer_hanging_cloth.phenomenon import make_simulator as hanging_simulator

    out: dict[str, Any] = {}
    renderer = make_renderer()
    sampled = renderer.sample_render_params(np.random.default_rng(11))
    zetas = {"default": {"image_size": 96}, "sampled": {**sampled, "image_size": (80, 112)}}
    for name, effects, scene, theta, seed in (CASES[1], CASES[4]):
        traj = first_frames(flag_simulator(effects, scene).simulate(theta, seed=seed), 8)
        for zeta_name, zeta in zetas.items():
            out[f"render/{name}/{zeta_name}"] = digest(renderer.render(traj, zeta).frames)
    renderer.close()
    out["render/zeta_sampled"] = hashlib.sha256(json.dumps(sampled, sort_keys=True).encode()).hexdigest()
    hanging = hanging_renderer()
    traj = first_frames(hanging_simulator().simulate({}, seed=2), 6)
    out["traj/hanging_cloth"] = digest(traj.vertices)
    out["render/hanging_cloth"] = digest(hanging.render(traj, {"image_size": 80}).frames)
    hanging.close()
    return out


def dataset() -> dict[str, Any]:
    """A tiny flag dataset through ``physinfer dataset generate`` (in this process's venv)."""
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "flagsim"
        cli = Path(sys.executable).parent / "physinfer"
        args = [str(cli), "dataset", "generate", "--plugin", "flag", "--out", str(root), "--sims", "2,1,1",
                "--renders-per-sim", "2", "--frames", "8", "--size", "48", "--gray", "--sims-per-unit", "2",
                "--workers", "0", "--seed", "5", "--json"]
        proc = subprocess.run(args, capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            raise SystemExit(f"dataset generate failed:\n{proc.stderr[-3000:]}")
        out["dataset/manifest"] = hashlib.sha256((root / "manifest.jsonl").read_bytes()).hexdigest()
        for shard in sorted((root / "shards").glob("*.npy")):
            out[f"dataset/shards/{shard.name}"] = hashlib.sha256(shard.read_bytes()).hexdigest()
        for path in sorted((root / "trajectories").glob("*.npz")):
            with np.load(path) as arrays:
                out[f"dataset/trajectories/{path.name}"] = {k: digest(arrays[k]) for k in sorted(arrays.files)}
        description = json.loads((root / "dataset.json").read_text())
        out["dataset/description"] = hashlib.sha256(json.dumps(description, sort_keys=True).encode()).hexdigest()
    return out


RUNNERS: dict[str, Callable[[], dict[str, Any]]] = {
    "traj": trajectories, "batch": batches, "render": renders, "dataset": dataset,
}


def main(argv: list[str] | None = None) -> int:
    """Record (``--save``) or compare (``--compare``) the fingerprint; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--save", type=Path, help="write the hashes to this JSON file")
    parser.add_argument("--compare", type=Path, help="compare with the hashes in this JSON file")
    parser.add_argument("--only", default=",".join(SECTIONS), help=f"comma-separated sections of {SECTIONS}")
    args = parser.parse_args(argv)
    sections = [s for s in args.only.split(",") if s]
    unknown = set(sections) - set(SECTIONS)
    if unknown:
        parser.error(f"unknown sections {sorted(unknown)}; choose from {SECTIONS}")
    hashes: dict[str, Any] = {}
    for section in sections:
        print(f"[check_bitwise] {section} ...", file=sys.stderr, flush=True)
        hashes.update(RUNNERS[section]())
    report: dict[str, Any] = {"hashes": hashes}
    status = 0
    if args.compare is not None:
        before = json.loads(args.compare.read_text())["hashes"]
        differing = sorted(k for k in hashes if k in before and before[k] != hashes[k])
        missing = sorted(k for k in hashes if k not in before)
        report.update(differing=differing, not_in_reference=missing, compared=len(hashes) - len(missing))
        status = 1 if differing or missing else 0
    if args.save is not None:
        args.save.write_text(json.dumps(report, indent=1, sort_keys=True))
    print(json.dumps(report, indent=1, sort_keys=True))
    return status


if __name__ == "__main__":
    raise SystemExit(main())
