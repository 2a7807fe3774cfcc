"""Can the embedder see a flag effect at all? Distances with the effect on vs off, no optimizer.

For each wind speed and flag effect (at the middle of the diagnose benchmark's realistic
strengths), a target is simulated with the effect on (seed 1000); ``K`` re-simulations of the
*same* θ with the effect on and ``K`` with it off (other seeds) are embedded, and their
distances to the target compared (medians and a one-sided Mann–Whitney p that "on" is
closer). When "off" is not farther than "on", the seed noise hides the effect from the
embedder even at the true base parameters, and no optimizer budget can make the
discrepancy workflow name it. ``--targets N`` repeats the comparison against N targets
(seeds 1000, 1001, ...; the same re-simulations) and gives the share of targets whose test
says "on" at p < 0.05: one clip is one draw of a random effect such as gusts. Each row also gives the **energy score** of either side,
``mean |x_i - y| - mean_{i≠j} |x_i - x_j| / 2`` (a strictly proper score of a predictive
distribution: it rewards a model whose re-simulations spread like the target's does, so a
random forcing such as gusts is not penalised for its spread) and a rank test on its
per-re-simulation terms. Runs on the diagnose benchmark's ``flag_lite`` (16×11 grid,
bending at 1×). Prints one JSON object: ``rows`` (wind, effect, on, off, p, energy_on,
energy_off, p_energy_on_lower, norm_on, norm_off, p_norm_on_greater; with ``--targets`` > 1
also share_on_closer, share_energy_on_lower and per_target).

``--features`` asks whether anything could see the effect: ``embedder`` (default) uses the
embedder; ``localisation`` the diagnosis's own localisation statistics (log band power and
log motion envelope per region, amplitude non-stationarity; :mod:`physinfer.discrepancy.localise`);
``trajectory`` skips rendering and compares the vertices themselves (per-vertex mean
position and standard deviation over the clip) — if that cannot tell "off" from "on", no
video feature can. ``mean_image`` is the clip's time-averaged
grayscale image at 16×16 (the mean shape, which the spectral embedders discard).
``slow_pose`` asks whether the *slow* motion carries an effect: the flag's mean position
(the centroid of its vertices, x and z) averaged over 1-s windows, and the standard
deviation of those window means — how much the whole flag lifts, droops and stretches
from one second to the next. Gusts make it breathe so; the flapping averages out.
``slow_image`` is the same question asked of the video: the 1-s window means of the
clip's gray image on a 4×4 grid of cells, and their standard deviation per cell.
Every row also gives the **size** of each side's feature vectors (``norm_on``,
``norm_off``, medians, and a rank test that "on" is larger): for the ``slow_*`` features
that is the amount of slow motion, whatever the target's own draw of it.

Example (the numbers in docs/benchmarks.md)::

    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_effect_visibility.py \\
        --embedder spectral --render-size 112 --frames 40 --seeds 6
    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_effect_visibility.py --features trajectory --frames 100
    # 8-s clips read whole by the spectral embedder
    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_effect_visibility.py \\
        --embedder spectral --render-size 112 --frames 200 --embedder-frames 200 --seeds 6
    # the slow breathing of the flag that gusts cause, on the vertices and in the video
    .venv/bin/python benchmarks/bench_effect_visibility.py --features slow_pose --frames 200 --seeds 16
    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_effect_visibility.py \\
        --features slow_image --frames 200 --seeds 16 --effects wind_gusts
    # how often one 16-s clip tells gusts from a steady wind (eight targets)
    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_effect_visibility.py --embedder spectral \\
        --frames 400 --embedder-frames 400 --seeds 16 --targets 8 --effects wind_gusts
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import bench_diagnose  # noqa: E402  (the flag_lite phenomenon and the realistic strengths)

from physinfer.discrepancy.decide import rank_test_less  # noqa: E402

#: Each effect switched off (its parameters' off values; the gusts' time scale is moot then).
OFF: dict[str, dict[str, float]] = {
    "wind_gusts": {"gust_intensity": 0.0, "gust_timescale": 0.7},
    "wind_shear": {"shear_exponent": 0.0},
    "wind_yaw": {"wind_yaw_deg": 0.0},
    "wind_inclination": {"wind_inclination_deg": 0.0},
}


def mid_strength(effect: str) -> dict[str, float]:
    """The middle of the benchmark's realistic range of each of the effect's parameters."""
    return {name: (lo + hi) / 2 for name, (lo, hi) in bench_diagnose.STRENGTHS[effect].items()}


def trajectory_features(vertices: np.ndarray) -> np.ndarray:
    """Per-vertex mean position and standard deviation over time of ``(T, V, 3)`` vertices."""
    v = np.asarray(vertices, dtype=np.float64)
    return np.concatenate([v.mean(axis=0).ravel(), v.std(axis=0).ravel()])


def window_means(series: np.ndarray, fps: float, window_s: float = 1.0) -> np.ndarray:
    """``(T, ...)`` → ``(W, ...)``: means over consecutive ``window_s`` windows (a partial last one dropped)."""
    width = max(1, int(round(window_s * fps)))
    n = len(series) // width
    if n < 2:
        raise SystemExit(f"slow features need at least two {window_s:g}-s windows; raise --frames")
    return series[: n * width].reshape(n, width, *series.shape[1:]).mean(axis=1)


def slow_pose_features(vertices: np.ndarray, fps: float) -> np.ndarray:
    """Standard deviation over 1-s windows of the window-mean centroid x and z (metres)."""
    centroid = np.asarray(vertices, dtype=np.float64).mean(axis=1)
    return window_means(centroid[:, [0, 2]], fps).std(axis=0)


def gray_cells(clip: Any, cells: int) -> np.ndarray:
    """``(T, cells, cells)``: the clip's gray level (64 px, 25 fps, ×100) averaged over square cells."""
    from physinfer.video import prepare_for_embedding

    video = np.asarray(prepare_for_embedding(clip, fps=25.0, n_frames=len(clip.frames), size=64), dtype=np.float64)
    side = 64 // cells
    return video.reshape(len(video), cells, side, cells, side).mean(axis=(2, 4)) * 100.0


def mean_image_features(clip: Any) -> np.ndarray:
    """The time-averaged gray image on a 16×16 grid (the mean shape)."""
    return gray_cells(clip, 16).mean(axis=0).ravel()


def slow_image_features(clip: Any) -> np.ndarray:
    """Standard deviation over 1-s windows of the window-mean gray level of 4×4 cells."""
    return window_means(gray_cells(clip, 4), 25.0).std(axis=0).ravel()


def localisation_features(clip: Any) -> np.ndarray:
    """The localisation statistics of a clip as one vector (log band power and log motion
    envelope per region, amplitude non-stationarity per region)."""
    from physinfer.discrepancy.localise import LocaliseConfig, spectral_maps

    maps = spectral_maps(clip, fps=clip.fps, n_frames=len(clip.frames), config=LocaliseConfig())
    return np.concatenate([
        np.log(maps.region_bands + 1e-9).ravel(), np.log(maps.envelope + 1e-9).ravel(), maps.nonstationarity().ravel()
    ])


def visibility(registry: Any, effect: str, wind: float, args: argparse.Namespace) -> dict[str, Any]:
    """Distances to an effect-on target from ``K`` re-simulations with the effect on and off."""
    from physinfer.evaluation import build_pipeline

    embedder = args.embedder if args.features == "embedder" else ""
    pipeline = build_pipeline(registry, "flag_visibility", effects=[effect], embedder=embedder,
                              embedder_frames=args.embedder_frames if embedder else None)
    base_space = pipeline.phenomenon.parameter_space
    theta = base_space.from_unit(np.zeros(len(base_space)))
    theta["wind_speed"] = wind
    zeta = {**pipeline.renderer.default_render_params, "image_size": args.render_size}

    def embed(params: dict[str, float], seed: int) -> np.ndarray:
        trajectory = pipeline.simulator.simulate(params, seed=seed)
        if args.features == "trajectory":
            return trajectory_features(trajectory.vertices)
        if args.features == "slow_pose":
            return slow_pose_features(trajectory.vertices, trajectory.fps)
        clip = pipeline.renderer.render(trajectory, zeta)
        if args.features == "slow_image":
            return slow_image_features(clip)
        if args.features == "mean_image":
            return mean_image_features(clip)
        return localisation_features(clip) if args.features == "localisation" else pipeline.embedder.embed(clip)

    t0 = time.perf_counter()
    strength = {**mid_strength(effect), **{k: v for k, v in args.strength.items() if k in OFF[effect]}}
    on, off = {**theta, **strength}, {**theta, **OFF[effect]}
    targets = [embed(on, 1000 + t) for t in range(args.targets)]
    x_on = np.stack([embed(on, s) for s in range(1, args.seeds + 1)])
    x_off = np.stack([embed(off, s) for s in range(1, args.seeds + 1)])
    pipeline.renderer.close()
    n_on, n_off = np.linalg.norm(x_on, axis=1), np.linalg.norm(x_off, axis=1)
    each = [target_comparison(x_on, x_off, target) for target in targets]
    row = {"wind": wind, "effect": effect, "strength": strength, **each[0]}
    if args.targets > 1:  # how often one clip tells "on" from "off": every target's own test
        row["share_on_closer"] = float(np.mean([c["p_on_closer"] < 0.05 for c in each]))
        row["share_energy_on_lower"] = float(np.mean([c["p_energy_on_lower"] < 0.05 for c in each]))
        row["per_target"] = each
    return {
        **row,
        "norm_on": float(np.median(n_on)),
        "norm_off": float(np.median(n_off)),
        "p_norm_on_greater": rank_test_less((-n_on).tolist(), (-n_off).tolist()),
        "wall_time_s": time.perf_counter() - t0,
    }


def target_comparison(x_on: np.ndarray, x_off: np.ndarray, target: np.ndarray) -> dict[str, float]:
    """Distances and energy scores of the "on" and "off" re-simulations against one target."""
    d_on, d_off = np.linalg.norm(x_on - target, axis=1), np.linalg.norm(x_off - target, axis=1)
    s_on, s_off = energy_scores(x_on, target), energy_scores(x_off, target)
    return {
        "on": float(np.median(d_on)),
        "off": float(np.median(d_off)),
        "off_over_on": float(np.median(d_off) / np.median(d_on)),
        "p_on_closer": rank_test_less(d_on.tolist(), d_off.tolist()),
        "energy_on": float(s_on.mean()),
        "energy_off": float(s_off.mean()),
        "energy_off_over_on": float(s_off.mean() / s_on.mean()),
        "p_energy_on_lower": rank_test_less(s_on.tolist(), s_off.tolist()),
    }


def energy_scores(samples: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Per-sample terms of the energy score ``E|X - y| - E|X - X'| / 2`` (their mean is the score)."""
    pairwise = np.linalg.norm(samples[:, None, :] - samples[None, :, :], axis=2)
    k = len(samples)
    return np.linalg.norm(samples - target, axis=1) - pairwise.sum(axis=1) / (2 * (k - 1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--embedder", default="spectral")
    parser.add_argument("--render-size", type=int, default=112)
    parser.add_argument("--frames", type=int, default=40, help="clip length (the SDN needs at least 60)")
    parser.add_argument("--embedder-frames", type=int, default=None,
                        help="frames a parameter-free embedder reads (default: its own; spectral 30)")
    parser.add_argument("--winds", default="3,6", help="wind speeds in m/s, comma-separated")
    parser.add_argument("--seeds", type=int, default=6, help="K re-simulations per side")
    parser.add_argument("--targets", type=int, default=1,
                        help="targets with the effect on (seeds 1000, 1001, ...); with more than one, each row "
                             "adds per_target and the share of targets whose test says 'on' (p < 0.05)")
    parser.add_argument("--strength", action="append", default=[], metavar="NAME=VALUE",
                        help="an effect parameter's value instead of the middle of the realistic range (repeatable)")
    parser.add_argument("--effects", default=",".join(OFF), help="effects to test, comma-separated")
    parser.add_argument("--features", choices=("embedder", "localisation", "trajectory", "mean_image", "slow_pose", "slow_image"), default="embedder",
                        help="what compares the clips (see the module docstring)")
    args = parser.parse_args()
    from physinfer.parameters import parse_float_assignments

    args.strength = parse_float_assignments(args.strength, "--strength")

    from physinfer.plugins import load_registry

    registry, _ = load_registry()
    registry.scoped("bench_effect_visibility").add_phenomenon(
        "flag_visibility", lambda **config: bench_diagnose.flag_lite(n_frames=args.frames, **config), "flag_lite"
    )
    rows = []
    for wind in (float(w) for w in args.winds.split(",")):
        for effect in (e.strip() for e in args.effects.split(",") if e.strip()):
            rows.append(visibility(registry, effect, wind, args))
            print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    print(json.dumps({"settings": vars(args), "rows": rows}))


if __name__ == "__main__":
    main()
