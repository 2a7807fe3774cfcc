"""Which flow recipe gives the flag's told-camera wind posterior the smallest error at
calibrated coverage? (issue 44, items 4 and 6)

Two steps, so that the sweep can run where there are many cores or a GPU:

``prepare`` writes ``DIR/pairs.npz`` — the flow inputs (spectral embedding as given, then the
six told render settings) and normalised θ of every ``--data`` training split and of the
first one's held-out split, read from the caches ``make posterior`` left (embedded when
missing) — and ``DIR/targets.json``: the flow inputs of ``bench_posterior_targets.py``'s
targets (the same seeds: wind 1–9.5 m/s, area weight 0.10–0.17, default camera told), clean
mp4 and degraded (a frame of ``--photo`` behind the flag, noise, CRF 35), as ``infer``
computes them, with the shipped estimator's own answer.

``sweep`` trains each recipe's members (one process and one thread each, ``--workers`` at a
time; a recipe on ``cuda`` runs one member at a time on the GPU), mixes a recipe's members
with equal weight (the shipped ``FlowEnsemble``) and scores the wind on the held-out clips
and on both target sets: 90 % coverage, median error of the posterior median, median 90 %
width; also each member alone and, for ten members, the mixture of the first five.

    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_flow_recipes.py prepare runs/flow-recipes \\
        --data runs/flag-posterior --data runs/flag-posterior-more --targets 100 --photo ../shared/realvideo/classroom_1m.mp4
    .venv/bin/python benchmarks/bench_flow_recipes.py sweep runs/flow-recipes --workers 15 --deadline 400

Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

SHIPPED = Path(__file__).parents[1] / "plugins/flag/physinfer_flag/data/posterior_camera.safetensors"
#: name: (density, hidden features, transforms, training sets, embedding-net width or None,
#: device, patience, members). ``tr`` is the first --data, ``more`` the second.
RECIPES: dict[str, tuple[str, int, int, str, int | None, str, int, int]] = {
    "maf800": ("maf", 64, 5, "tr", None, "cpu", 20, 10),  # the shipped recipe (members 0-4)
    "maf800cuda": ("maf", 64, 5, "tr", None, "cuda", 20, 5),
    "maf1600": ("maf", 64, 5, "tr+more", None, "cpu", 20, 10),
    "nsf800": ("nsf", 64, 5, "tr", None, "cpu", 20, 10),
    "nsf1600": ("nsf", 64, 5, "tr+more", None, "cpu", 20, 10),
    "maf1600p50": ("maf", 64, 5, "tr+more", None, "cpu", 50, 10),
    "mafemb1600": ("maf", 64, 5, "tr+more", 32, "cpu", 50, 10),
    "maf800wa": ("maf", 64, 5, "tr", None, "cpu", 20, 10),  # the identified pair only (FOCUS)
    "maf1600wa": ("maf", 64, 5, "tr+more", None, "cpu", 20, 10),
}
#: Recipes whose flow learns only these parameters' joint posterior (the marginal of the
#: others): the 15 bending multipliers the clip does not identify take no capacity.
FOCUS: dict[str, tuple[str, ...]] = {
    "maf800wa": ("wind_speed", "area_weight"),
    "maf1600wa": ("wind_speed", "area_weight"),
}
SAMPLES = 1000  # per member and input


# ------------------------------------------------------------------------------ prepare


def prepare(folder: Path, data: list[Path], n_targets: int, photo: str | None) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    from physinfer.posterior.estimator import PosteriorEstimator

    shipped = PosteriorEstimator.load(SHIPPED)
    arrays = {}
    for tag, root, split in [("tr", data[0], "train"), ("te", data[0], "test")] + [
        ("more", root, "train") for root in data[1:2]
    ]:
        conditions, theta = _pairs(shipped, root, split)
        arrays[f"{tag}_c"], arrays[f"{tag}_t"] = conditions, theta
        print(f"{tag}: {conditions.shape[0]} clips from {root}", file=sys.stderr)
    np.savez_compressed(folder / "pairs.npz", **arrays)
    (folder / "targets.json").write_text(json.dumps(_target_inputs(n_targets, photo, folder)))


def _pairs(shipped: Any, root: Path, split: str) -> tuple[np.ndarray, np.ndarray]:
    """The flow inputs and θ of a split, embedded as the shipped estimator's training was."""
    from physinfer.as_given import CameraModel
    from physinfer.plugins import load_registry
    from physinfer.posterior.features import TargetPath, embed_dataset
    from physinfer.posterior.loading import build_embedder

    c = shipped.config
    pipeline = build_embedder(
        load_registry()[0], "flag", embedder=c.embedder, embedder_frames=c.frames_option, weights=None, device="cpu"
    )
    info = {"embedder": c.embedder, "embedder_frames": c.embedder_frames, "embedder_fps": c.embedder_fps, "probe": c.probe}
    camera = CameraModel.from_dict(c.targets["as_given"]["camera"])
    path = TargetPath(pipeline.phenomenon, camera, c.targets["as_given"]["seed"])
    pairs = embed_dataset(root, split, pipeline.embedder, info, as_given=path).with_render_inputs(c.render_inputs)
    pipeline.renderer.close()
    return pairs.conditions.astype(np.float32), pairs.theta_unit.astype(np.float32)


def _target_inputs(n: int, photo: str | None, folder: Path) -> dict[str, list[dict[str, Any]]]:
    """bench_posterior_targets' targets through ``infer`` (the shipped estimator told the
    camera), keeping the flow input ``infer`` sampled at."""
    import bench_posterior_targets as bench

    from physinfer.evaluation import build_pipeline
    from physinfer.plugins import load_registry
    from physinfer.posterior import estimator as estimator_module
    from physinfer.video import write_video

    seen: list[np.ndarray] = []
    original = estimator_module.PosteriorEstimator.input_check

    def keep(self: Any, x: np.ndarray) -> Any:
        seen.append(np.asarray(x, np.float32).copy())
        return original(self, x)

    estimator_module.PosteriorEstimator.input_check = keep  # type: ignore[method-assign]
    registry = load_registry()[0]
    pipeline = build_pipeline(registry, "flag", embedder="")
    names = ["wind_speed", "area_weight"]
    rows: dict[str, list[dict[str, Any]]] = {"clean": [], "degraded": []}
    with tempfile.TemporaryDirectory(prefix="bench-recipes-") as tmp:
        for i in range(n):
            theta, trajectory = bench.make_target(pipeline, "flag", i)
            clip = pipeline.renderer.render(trajectory, pipeline.renderer.default_render_params)
            h, w = clip.frames.shape[1:3]
            background = bench.photo(photo, (h + 16, w + 16), i)
            frames = bench.degraded(pipeline, trajectory, background, np.random.default_rng(bench.THETA_SEED + i))
            cases = {
                "clean": write_video(Path(tmp) / f"t{i}.mp4", clip),
                "degraded": write_video(Path(tmp) / f"d{i}.mp4", frames, clip.fps, crf=35),
            }
            told = bench.told_camera(pipeline.renderer)
            for condition, video in cases.items():
                seen.clear()
                row = bench.infer_row(registry, "flag", video, None, theta, names, {}, Path(tmp) / f"o{i}{condition}", told)
                wind = row["params"]["wind_speed"]
                rows[condition].append({"target": i, "wind": theta["wind_speed"], "x": seen[0].tolist(),
                                        "shipped": {k: wind[k] for k in ("error", "covered90", "width90")}})  # fmt: skip
            print(f"target {i}: shipped errors {rows['clean'][-1]['shipped']['error']:.3f} (clean), "
                  f"{rows['degraded'][-1]['shipped']['error']:.3f} (degraded)", file=sys.stderr, flush=True)  # fmt: skip
    return rows


# -------------------------------------------------------------------------------- sweep


def member(folder: Path, name: str, seed: int) -> None:
    """Train member ``seed`` of recipe ``name`` and keep its wind samples at every input."""
    import torch

    torch.set_num_threads(1)
    from physinfer.posterior.estimator import NetworkConfig, PosteriorEstimator
    from physinfer.posterior.features import EmbeddedSet
    from physinfer.posterior.training import train_estimator

    density, hidden, transforms, sets, embedding, device, patience, _ = RECIPES[name]
    pairs, targets = _load(folder)
    space = PosteriorEstimator.load(SHIPPED).parameter_space
    conditions = np.concatenate([pairs[f"{k}_c"] for k in sets.split("+")])
    theta = np.concatenate([pairs[f"{k}_t"] for k in sets.split("+")])
    if name in FOCUS:
        from physinfer.parameters import ParameterSpace

        columns = [space.names.index(n) for n in FOCUS[name]]
        space, theta = ParameterSpace([list(space)[i] for i in columns]), theta[:, columns]
    network = NetworkConfig(density=density, hidden_features=hidden, num_transforms=transforms, stop_after_epochs=patience)
    if embedding:  # an MLP between the inputs and the flow, trained with it
        from sbi.neural_nets import posterior_nn
        from sbi.neural_nets.embedding_nets import FCEmbedding

        net = FCEmbedding(input_dim=conditions.shape[1], output_dim=embedding, num_layers=2, num_hiddens=128)
        NetworkConfig.builder = lambda self: posterior_nn(  # type: ignore[method-assign]
            model=self.density, hidden_features=self.hidden_features, num_transforms=self.num_transforms, embedding_net=net
        )
    identity = {"plugin": "flag", "embedder": "spectral", "embedder_frames": 60, "embedder_fps": 25.0,
                "frames_option": 60, "weights": None, "probe": [], "clip_seconds": 2.4}  # fmt: skip
    started = time.perf_counter()
    estimator = train_estimator(
        EmbeddedSet(space, theta, conditions, np.arange(len(theta)), folder), identity,
        network=network, seed=seed, device=device,
    )  # fmt: skip
    seconds = time.perf_counter() - started
    wind = list(space)[space.names.index("wind_speed")]
    samples = {
        tag: wind.from_unit(estimator.sample_unit_batched(x, SAMPLES, seed=seed)[:, :, space.names.index("wind_speed")])
        for tag, x in _inputs(pairs, targets).items()
    }
    np.savez(folder / "members" / f"{name}-{seed}.npz", seconds=seconds, epochs=estimator.config.training["epochs"], **samples)


def _load(folder: Path) -> tuple[Any, dict[str, Any]]:
    return np.load(folder / "pairs.npz", allow_pickle=False), json.loads((folder / "targets.json").read_text())


def _inputs(pairs: Any, targets: dict[str, Any]) -> dict[str, np.ndarray]:
    inputs = {"held_out": pairs["te_c"]}
    inputs.update({c: np.array([r["x"] for r in rows], np.float32) for c, rows in targets.items()})
    return inputs


def score(samples: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """90 % coverage, median error of the median and median 90 % width of ``(S, B)`` samples."""
    low, high = np.quantile(samples, [0.05, 0.95], axis=0)
    return {
        "coverage90": round(float(np.mean((low <= truth) & (truth <= high))), 3),
        "median_error": round(float(np.median(np.abs(np.median(samples, axis=0) - truth))), 4),
        "median_width90": round(float(np.median(high - low)), 3),
    }


def summarise(folder: Path) -> dict[str, Any]:
    from physinfer.posterior.estimator import PosteriorEstimator

    pairs, targets = _load(folder)
    space = PosteriorEstimator.load(SHIPPED).parameter_space
    wind = space.names.index("wind_speed")
    truths = {"held_out": list(space)[wind].from_unit(pairs["te_t"][:, wind])}
    truths.update({c: np.array([r["wind"] for r in rows]) for c, rows in targets.items()})
    out: dict[str, Any] = {"shipped": {c: {
        "coverage90": float(np.mean([r["shipped"]["covered90"] for r in rows])),
        "median_error": float(np.median([r["shipped"]["error"] for r in rows])),
        "median_width90": float(np.median([r["shipped"]["width90"] for r in rows])),
    } for c, rows in targets.items()}}  # fmt: skip
    for name in RECIPES:
        files = sorted((folder / "members").glob(f"{name}-*.npz"), key=lambda f: int(f.stem.rsplit("-", 1)[1]))
        if not files:
            continue
        members = [np.load(f) for f in files]
        first5 = members[:5] if len(members) > 5 and int(files[4].stem.rsplit("-", 1)[1]) == 4 else []
        row: dict[str, Any] = {
            "members": len(members), "train_seconds": [round(float(m["seconds"]), 1) for m in members],
            "epochs": [int(m["epochs"]) for m in members],
        }  # fmt: skip
        for tag, truth in truths.items():
            row[tag] = score(np.concatenate([m[tag] for m in members]), truth)
            if first5:
                row[f"{tag}_first5"] = score(np.concatenate([m[tag] for m in first5]), truth)
            row[f"{tag}_each_member_error"] = [score(m[tag], truth)["median_error"] for m in members]
        out[name] = row
    return out


def sweep(folder: Path, workers: int, deadline: float, recipes: list[str]) -> dict[str, Any]:
    (folder / "members").mkdir(exist_ok=True)
    started = time.perf_counter()
    jobs = [(n, s) for s in range(10) for n in recipes if s < RECIPES[n][7]]  # every recipe gets members early
    gpu = [j for j in jobs if RECIPES[j[0]][5] == "cuda"]
    cpu = [j for j in jobs if RECIPES[j[0]][5] != "cuda"]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    running: list[tuple[tuple[str, int], subprocess.Popen[bytes]]] = []

    def launch(job: tuple[str, int]) -> None:
        log = (folder / "members" / f"{job[0]}-{job[1]}.log").open("w")
        command = [sys.executable, __file__, "member", str(folder), job[0], str(job[1])]
        running.append((job, subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT)))

    while (cpu or gpu or running) and time.perf_counter() - started < deadline:
        if gpu and not any(RECIPES[j[0]][5] == "cuda" for j, _ in running):
            launch(gpu.pop(0))
        while cpu and sum(RECIPES[j[0]][5] != "cuda" for j, _ in running) < workers:
            launch(cpu.pop(0))
        time.sleep(1.0)
        for item in list(running):
            if item[1].poll() is not None:
                running.remove(item)
                print(f"{time.perf_counter() - started:5.0f} s: {item[0]} rc={item[1].returncode}", file=sys.stderr, flush=True)
    for job, process in running:
        process.kill()
        print(f"stopped at the deadline: {job}", file=sys.stderr)
    return {**summarise(folder), "unfinished": [list(j) for j in cpu + gpu] + [list(j) for j, _ in running],
            "seconds": round(time.perf_counter() - started)}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="step", required=True)
    p = sub.add_parser("prepare")
    p.add_argument("folder", type=Path)
    p.add_argument("--data", type=Path, action="append", required=True, help="dataset (first: train + held-out)")
    p.add_argument("--targets", type=int, default=100)
    p.add_argument("--photo", default=None, help="a video whose middle frame is the degraded targets' background")
    s = sub.add_parser("sweep")
    s.add_argument("folder", type=Path)
    s.add_argument("--workers", type=int, default=max(1, (os.cpu_count() or 2) - 1))
    s.add_argument("--deadline", type=float, default=3600.0, help="seconds; unfinished members are left out")
    s.add_argument("--recipes", nargs="*", default=None, help=f"of {', '.join(RECIPES)} (default: all but cuda without one)")
    m = sub.add_parser("member")
    m.add_argument("folder", type=Path)
    m.add_argument("name")
    m.add_argument("seed", type=int)
    args = parser.parse_args()
    if args.step == "prepare":
        prepare(args.folder, args.data, args.targets, args.photo)
        return
    if args.step == "member":
        member(args.folder, args.name, args.seed)
        return
    import torch

    recipes = args.recipes or [n for n in RECIPES if RECIPES[n][5] != "cuda" or torch.cuda.is_available()]
    result = sweep(args.folder, args.workers, args.deadline, recipes)
    result.update(benchmark="flow_recipes", date=time.strftime("%Y-%m-%d"), machine={
        "cpus": os.cpu_count(), "platform": platform.platform(),
        "gpu": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
    })  # fmt: skip
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
