"""Real-video conditions (issue 23 item 4): the shipped posterior on degraded held-out flags.

Held-out targets: θ uniform over the prior and ζ from the renderer's dataset distribution,
from seeds no dataset or benchmark uses (θ and ζ from ``300_000 + i``, the simulation from
``400_000 + i``). Each is simulated once at 300 fps (the 25-fps integration step; 25, 30, 50
and 60 fps are every 12th, 10th, 6th and 5th frame of it) and degraded per condition; the
method never sees ζ. Pipeline per condition: degrade → ``prepare_clip`` (automatic framing,
shake, resampling to 25 fps) → ``infer`` with the shipped amortized estimator (embed +
2,000 samples). The baseline ``clean (oracle framing)`` is the clean render itself, as the
posterior's calibration saw it. Also reported per condition: the render-parameter estimate
(physinfer.render_estimate) against the true camera, and how far the condition moves the
embedding from the clean render's (squared distance; 1 m/s of wind moves it 0.11).

    PYOPENGL_PLATFORM=egl nice -n 10 .venv/bin/python benchmarks/bench_real_conditions.py --targets 12 --rows rows.json
    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_real_conditions.py --quick

Prints one JSON object (per condition: median wind error of the posterior median, share
within 0.5 m/s, 90 % coverage, ζ estimate errors, embedding shift) and a table on stderr.
Every prepared condition is reported as ``prepare`` ships (the static background frozen)
and ``(no freeze)``. ``--sizes``: targets whose flag length and height are drawn too
(log-uniform over the shipped sizes estimator's ranges, 0.9-3 m × 0.6-2 m), simulated in
that scene and inferred with the estimator ``infer --scene-set`` picks, given the size; a
few conditions (``SIZE_CONDITIONS``). The default (6 targets) takes about 20 min on the busy 2-core machine;
``--quick`` (1 target, 4 conditions) about a minute.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from real_conditions import (  # noqa: E402
    composite,
    h264,
    photo_background,
    render_rgba,
    sensor_noise,
    shake,
    white_balance,
)

from physinfer.errors import UserInputError  # noqa: E402
from physinfer.evaluation import squared_distance  # noqa: E402
from physinfer.framing import PrepareSettings, prepare_clip  # noqa: E402
from physinfer.types import Clip, Trajectory  # noqa: E402

THETA_SEED, SIM_SEED = 300_000, 400_000
#: The flag sizes ``--sizes`` draws (the shipped sizes estimator's ranges).
SIZE_RANGES = {"flag_length": (0.9, 3.0), "flag_height": (0.6, 2.0)}
SIZE_CONDITIONS = (
    "clean (oracle framing)",
    "clean → prepare",
    "H.264 CRF 35",
    "1920×1080 off-centre",
    "phone (all, 1080p 30 fps)",
)
SIM_FPS, FRAMES_25 = 300.0, 60
STEP = {25: 12, 30: 10, 50: 6, 60: 5}


def make_target(phenomenon: Any, renderer: Any, index: int, sized: bool = False) -> dict[str, Any]:
    """θ, ζ (and with ``sized`` the flag's size) and the 300-fps trajectory of held-out target ``index``."""
    from physinfer.scene import default_scene, sample_scene
    from physinfer_flag.phenomenon import scene_config
    from physinfer_flag.simulator import make_simulator

    space = phenomenon.parameter_space
    rng = np.random.default_rng(THETA_SEED + index)
    truth = space.from_unit(rng.uniform(-1.0, 1.0, len(space)))
    zeta = renderer.sample_render_params(rng)
    scene = {**default_scene(phenomenon), **sample_scene(rng, SIZE_RANGES)} if sized else None
    config = scene_config(scene) if scene else {}
    simulator = make_simulator(fps=SIM_FPS, n_frames=FRAMES_25 * 12, **config)
    return {
        "truth": truth,
        "zeta": zeta,
        "scene": scene,
        "trajectory": simulator.simulate(truth, seed=SIM_SEED + index),
        "rng": rng,
    }


def at_fps(trajectory: Trajectory, fps: int) -> Trajectory:
    step = STEP[fps]
    return Trajectory(
        trajectory.vertices[::step], trajectory.faces, SIM_FPS / step, trajectory.extras
    )


def conditions(
    target: dict[str, Any], renderer: Any, seed: int
) -> dict[str, Callable[[], tuple[Clip, bool]]]:
    """``{name: make()}``; ``make()`` gives the degraded clip and whether to prepare it."""
    zeta, trajectory, rng = target["zeta"], target["trajectory"], np.random.default_rng(seed)
    cache: dict[str, Any] = {}

    def rgb(fps: int = 25) -> np.ndarray:
        if f"rgb{fps}" not in cache:
            cache[f"rgb{fps}"] = renderer.render(at_fps(trajectory, fps), zeta).frames
        return cache[f"rgb{fps}"]

    def wide(size: tuple[int, int], side: int, fps: int = 25, moved: bool = False) -> np.ndarray:
        key = f"rgba{side}@{fps}"
        if key not in cache:
            cache[key] = render_rgba(
                renderer, at_fps(trajectory, fps), {**zeta, "image_size": side}
            )
        h, w = size
        background = photo_background(h + 16, w + 16, seed)
        # Off-centre: anywhere that keeps the square inside, but not around the middle.
        x = int(rng.choice([rng.uniform(0.03, 0.3), rng.uniform(0.55, 0.95)]) * (w - side))
        y = int(rng.uniform(0.05, 0.9) * (h - side))
        shifts = shake(len(cache[key]), rng) if moved else None
        return composite(cache[key], background, (x, y), shifts)

    def phone() -> np.ndarray:
        frames = wide((1080, 1920), 320, fps=30, moved=True)
        return h264(sensor_noise(white_balance(frames), rng), 30.0)

    return {
        "clean (oracle framing)": lambda: (Clip(rgb(), 25.0), False),
        "clean → prepare": lambda: (Clip(rgb(), 25.0), True),
        "H.264 CRF 35": lambda: (Clip(h264(rgb(), 25.0), 25.0), True),
        "white balance": lambda: (Clip(white_balance(rgb()), 25.0), True),
        "sensor noise": lambda: (Clip(sensor_noise(rgb(), rng), 25.0), True),
        "noise + H.264": lambda: (Clip(h264(sensor_noise(rgb(), rng), 25.0), 25.0), True),
        "30 fps": lambda: (Clip(rgb(30), 30.0), True),
        "50 fps": lambda: (Clip(rgb(50), 50.0), True),
        "60 fps": lambda: (Clip(rgb(60), 60.0), True),
        "photo background": lambda: (Clip(wide((224, 224), 224)[:, :, :], 25.0), True),
        "640×360 off-centre": lambda: (Clip(wide((360, 640), 150), 25.0), True),
        "640×360 + shake": lambda: (Clip(wide((360, 640), 150, moved=True), 25.0), True),
        "1920×1080 off-centre": lambda: (Clip(wide((1080, 1920), 300), 25.0), True),
        "phone (all, 1080p 30 fps)": lambda: (Clip(phone(), 30.0), True),
    }


CLEAN = "clean (oracle framing)"

UNFROZEN = " (no freeze)"
"""Suffix of a prepared condition measured without freezing the static background
(``prepare --no-freeze-background``): what the fix in prepare changes."""


def evaluate(
    clip: Clip,
    truth: dict[str, float],
    zeta: dict[str, Any],
    ctx: dict[str, Any],
    seed: int,
    scene: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Posterior of ``clip`` (embedding, samples), its wind error and the ζ estimate."""
    from physinfer.posterior.summary import marginals
    from physinfer.posterior.workflow import embed_target

    x = embed_target(ctx["estimator"], ctx["embedder"], clip)
    samples = ctx["estimator"].sample_unit(ctx["estimator"].condition(x, scene), 2000, seed=seed)
    wind = marginals(samples, ctx["estimator"].parameter_space)["wind_speed"]
    try:
        zest = ctx["render_estimator"].estimate(x)["values"]
    except UserInputError:  # fitted on another embedder's embeddings than the posterior's
        nan = float("nan")
        zest = {"camera_azimuth_deg": nan, "camera_elevation_deg": nan, "framing": nan}
    return {
        "embedding": x,
        "wind_median": float(wind["median"]),
        "wind_error": abs(float(wind["median"]) - truth["wind_speed"]),
        "covered90": bool(wind["ci90"][0] <= truth["wind_speed"] <= wind["ci90"][1]),
        "ci90_width": float(wind["ci90"][1] - wind["ci90"][0]),
        "azimuth_error": abs(zest["camera_azimuth_deg"] - zeta["camera_azimuth_deg"]),
        "elevation_error": abs(zest["camera_elevation_deg"] - zeta["camera_elevation_deg"]),
        "framing_estimate": zest["framing"],
    }


def run_target(index: int, ctx: dict[str, Any], quick: bool) -> list[dict[str, Any]]:
    target = make_target(ctx["phenomenon"], ctx["renderer"], index, sized=ctx["sized"])
    rows, clean_x = [], None
    settings = PrepareSettings(size=ctx["embedder"].size, fps=ctx["embedder"].fps)
    unfrozen = replace(settings, freeze_background=False)
    for name, make in conditions(target, ctx["renderer"], seed=THETA_SEED + index).items():
        if quick and name not in ctx["quick_conditions"]:
            continue
        if ctx["sized"] and name not in SIZE_CONDITIONS:
            continue
        t0 = time.perf_counter()
        clip, prepare = make()
        t1 = time.perf_counter()
        row: dict[str, Any] = {
            "target": index,
            "condition": name,
            "truth_wind": target["truth"]["wind_speed"],
            **({"scene": target["scene"]} if target["scene"] else {}),
        }
        try:
            variants = {name: clip}
            if prepare:  # as shipped (the background frozen), and without the freeze
                framing = ctx["phenomenon"].framing
                prepared = prepare_clip(clip, framing=framing, settings=settings)
                raw = prepare_clip(clip, framing=framing, settings=unfrozen)
                variants = {name: prepared.clip, name + UNFROZEN: raw.clip}
                row["square"] = [round(v, 1) for v in prepared.square]
                row["static_background"] = prepared.static
            t2 = time.perf_counter()
            for label, c in variants.items():
                result = evaluate(c, target["truth"], target["zeta"], ctx, seed=index, scene=target["scene"])
                x = result.pop("embedding")
                if label == "clean (oracle framing)":
                    clean_x = x
                shift = squared_distance(x, clean_x) if clean_x is not None else None
                rows.append(
                    {
                        **row,
                        "condition": label,
                        **result,
                        "embedding_shift": shift,
                        "seconds": {
                            "degrade": t1 - t0,
                            "prepare": t2 - t1,
                            "infer": time.perf_counter() - t2,
                        },
                    }
                )
        except UserInputError as exc:  # a refusal is a result: the condition broke the pipeline
            rows.append({**row, "refused": str(exc)})
        last = next(r for r in rows if r["condition"] == name) if rows else {}
        print(
            f"target {index} {name}: {last.get('wind_error', last.get('refused'))}",
            file=sys.stderr,
            flush=True,
        )
    return rows


def summarise(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per condition; ``median_moved`` is the paired statistic: how far the posterior median
    moved from the same target's clean one (m/s), free of how hard each target is."""
    clean = {
        r["target"]: r["wind_median"]
        for r in rows
        if r["condition"] == CLEAN and "wind_median" in r
    }
    out: dict[str, dict[str, Any]] = {}
    for name in dict.fromkeys(r["condition"] for r in rows):
        done = [r for r in rows if r["condition"] == name and "wind_error" in r]
        n_all = sum(r["condition"] == name for r in rows)
        if not done:
            out[name] = {"n": 0, "refused": n_all}
            continue
        err = np.array([r["wind_error"] for r in done])
        shifts = [r["embedding_shift"] for r in done if r["embedding_shift"] is not None]
        out[name] = {
            "n": len(done),
            "refused": n_all - len(done),
            "median_wind_error": float(np.median(err)),
            "within_0.5": float(np.mean(err <= 0.5)),
            "coverage90": float(np.mean([r["covered90"] for r in done])),
            "median_ci90_width": float(np.median([r["ci90_width"] for r in done])),
            "median_azimuth_error": float(np.nanmedian([r["azimuth_error"] for r in done])),
            "median_elevation_error": float(np.nanmedian([r["elevation_error"] for r in done])),
            "median_framing_estimate": float(np.nanmedian([r["framing_estimate"] for r in done])),
            "median_embedding_shift": float(np.median(shifts)) if shifts else None,
            "median_moved": float(
                np.median(
                    [
                        abs(r["wind_median"] - clean[r["target"]])
                        for r in done
                        if r["target"] in clean
                    ]
                )
            )
            if any(r["target"] in clean for r in done)
            else None,
        }
    return out


def table(summary: dict[str, dict[str, Any]]) -> str:
    lines = [
        "| condition | n | median wind error (m/s) | within 0.5 m/s | 90 % coverage "
        "| moved from clean (m/s) | embedding shift |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, s in summary.items():
        if not s["n"]:
            lines.append(f"| {name} | 0 ({s['refused']} refused) | – | – | – | – | – |")
            continue
        refused = f" ({s['refused']} refused)" if s["refused"] else ""
        lines.append(
            f"| {name} | {s['n']}{refused} | {s['median_wind_error']:.2f} | {s['within_0.5']:.2f} | "
            f"{s['coverage90']:.2f} | {s['median_moved']:.2f} | {s['median_embedding_shift']:.2f} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--targets", type=int, default=6)
    parser.add_argument("--first", type=int, default=0, help="index of the first target")
    parser.add_argument(
        "--quick", action="store_true", help="1 target, 4 conditions (a smoke test)"
    )
    parser.add_argument(
        "--rows", type=Path, default=None, help="also write every row to this JSON file"
    )
    parser.add_argument(
        "--sizes", action="store_true", help="flags of drawn sizes, the sizes estimator, a few conditions"
    )
    args = parser.parse_args()

    from physinfer.plugins import load_registry
    from physinfer.posterior.workflow import estimator_embedder, load_estimator
    from physinfer.render_estimate import RenderEstimator, render_estimator_path

    start = time.perf_counter()
    registry, _ = load_registry()
    phenomenon = registry.phenomenon("flag")
    if args.sizes:  # the estimator infer picks for a flag of another size (any in the ranges)
        from physinfer.scene import default_scene

        other = {**default_scene(phenomenon), "flag_length": 2.0, "flag_height": 1.3}
        estimator, path = load_estimator(registry, "flag", None, "cpu", scene=other)
        estimator.check_scene(phenomenon, other, path)
    else:
        estimator, path = load_estimator(registry, "flag", None, "cpu")
    pipeline = estimator_embedder(registry, estimator, "cpu")
    ctx = {
        "phenomenon": phenomenon,
        "renderer": pipeline.renderer,
        "embedder": pipeline.embedder,
        "estimator": estimator,
        "render_estimator": RenderEstimator.load(render_estimator_path(phenomenon)),
        "sized": args.sizes,
        "quick_conditions": (
            "clean (oracle framing)",
            "clean → prepare",
            "H.264 CRF 35",
            "640×360 off-centre",
        ),
    }
    n = 1 if args.quick else args.targets
    rows: list[dict[str, Any]] = []
    for i in range(args.first, args.first + n):
        rows += run_target(i, ctx, args.quick)
        if args.rows:  # after every target, so a long run can be read while it goes
            args.rows.write_text(json.dumps(rows, indent=1))
    pipeline.renderer.close()
    summary = summarise(rows)
    print(table(summary), file=sys.stderr)
    print(
        json.dumps(
            {
                "benchmark": "real_conditions",
                "estimator": str(path),
                "targets": n,
                "first": args.first,
                "conditions": summary,
                "seconds": time.perf_counter() - start,
                "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, {platform.system()}",
                "load_average": os.getloadavg()[0],
            }
        )
    )


if __name__ == "__main__":
    main()
