"""How much each render parameter ζ moves the flag's embedding, against 1 m/s of wind.

Issue 23 item 2 asks to estimate from the target only the ζ components the embedding is
sensitive to. For ``--seeds`` trajectories at ``--wind`` (and as many at ``--wind + 1``),
every component is set to the two ends of the renderer's dataset range
(``FlagRenderer.sample_render_params``) with the rest at the default ζ, and the *same*
trajectory is rendered at both ends: the mean squared embedding distance between the two
renders is that component's effect (no seed noise in it). The wind's effect is the mean
squared distance between clips 1 m/s apart (different seeds), next to the seed-to-seed floor
at one wind. Components whose full-range effect is well under the wind's are not worth
estimating.

Usage: ``PYOPENGL_PLATFORM=egl nice -n 10 python benchmarks/bench_zeta_sensitivity.py --seeds 3``.
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import sys
import time

import numpy as np

from physinfer.evaluation import build_pipeline, squared_distance
from physinfer.plugins import load_registry

#: ``{label: (low ζ overrides, high ζ overrides)}`` over the dataset's ranges.
COMPONENTS: dict[str, tuple[dict, dict]] = {
    "camera_elevation_deg -15↔10": (
        {"camera_elevation_deg": -15.0},
        {"camera_elevation_deg": 10.0},
    ),
    "camera_azimuth_deg -15↔15": ({"camera_azimuth_deg": -15.0}, {"camera_azimuth_deg": 15.0}),
    "fov_deg 30↔50": ({"fov_deg": 30.0}, {"fov_deg": 50.0}),
    "framing 0.9↔1.35": ({"framing": 0.9}, {"framing": 1.35}),
    "light_intensity 1.8↔3.5": ({"light_intensity": 1.8}, {"light_intensity": 3.5}),
    "ambient_intensity 0.2↔0.45": ({"ambient_intensity": 0.2}, {"ambient_intensity": 0.45}),
    "light_direction left↔right": (
        {"light_direction": (-0.6, 0.5, -0.62)},
        {"light_direction": (0.6, 0.5, -0.62)},
    ),
    "texture netherlands↔germany": ({"texture": "netherlands"}, {"texture": "germany"}),
    "background sky_cloudy↔trees": ({"background": "sky_cloudy"}, {"background": "trees"}),
}


def embed_all(pipeline, trajectories, zeta) -> np.ndarray:
    """``(S, D)`` embeddings of every trajectory rendered at ``zeta``."""
    return np.stack(
        [pipeline.embedder.embed(pipeline.renderer.render(t, zeta)) for t in trajectories]
    )


def mean_pairs(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean([squared_distance(x, y) for x, y in zip(a, b, strict=True)]))


def mean_cross(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean([squared_distance(x, y) for x in a for y in b]))


def mean_within(e: np.ndarray) -> float:
    return float(np.mean([squared_distance(a, b) for a, b in itertools.combinations(e, 2)]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--wind", type=float, default=5.0)
    args = parser.parse_args()
    registry, _ = load_registry()
    pipeline = build_pipeline(registry, "flag")
    space = pipeline.simulator.parameter_space
    base = space.from_unit(np.zeros(len(space)))
    seeds = list(range(1, args.seeds + 1))
    start = time.perf_counter()
    trajectories = {
        w: [pipeline.simulator.simulate({**base, "wind_speed": w}, seed=s) for s in seeds]
        for w in (args.wind, args.wind + 1.0)
    }
    default = dict(pipeline.renderer.default_render_params)
    e_default = {w: embed_all(pipeline, t, default) for w, t in trajectories.items()}
    wind = {
        "between": mean_cross(e_default[args.wind], e_default[args.wind + 1.0]),
        "floor": 0.5 * sum(mean_within(e) for e in e_default.values()),
    }
    print(f"wind ±1 m/s: {wind}", file=sys.stderr, flush=True)
    rows = {}
    for label, (low, high) in COMPONENTS.items():
        e_low = embed_all(pipeline, trajectories[args.wind], {**default, **low})
        e_high = embed_all(pipeline, trajectories[args.wind], {**default, **high})
        d = mean_pairs(e_low, e_high)
        rows[label] = {"distance": d, "per_wind_1ms": d / wind["between"]}
        print(f"{label}: {d:.3f} ({d / wind['between']:.2f}× 1 m/s)", file=sys.stderr, flush=True)
    pipeline.renderer.close()
    print(
        json.dumps(
            {
                "benchmark": "zeta_sensitivity",
                "embedder": pipeline.phenomenon.default_embedder,
                "wind": args.wind,
                "seeds": args.seeds,
                "wind_1ms": wind,
                "components": rows,
                "seconds": time.perf_counter() - start,
                "machine": f"{platform.machine()}, {os.cpu_count()} CPUs",
                "load_average": os.getloadavg()[0],
            }
        )
    )


if __name__ == "__main__":
    main()
