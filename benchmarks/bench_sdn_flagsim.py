"""SDN and spectral-baseline accuracy on a generated FlagSim set, front end computed once.

For each input length in ``--frames`` the fixed front end runs once over every clip of
the train, val and test splits and its ``(4, size/2, size/2)`` maps are cached under
``--out`` (``features/<n>f-<split>.npy`` with a JSON sidecar of the front-end settings).
From the cache, per length: the spectral baseline's test triplet accuracy and wind-speed
regression (head fitted on train); for the lengths in ``--sdn-frames`` an SDN trained on
train (selected on val, resumable in ``<out>/sdn-<n>f``) and its test triplet accuracy and
wind regression. ``physinfer train`` / ``evaluate`` recompute the front end on every call;
on 2 shared cores that is most of the time, hence this script for the tables.

Prints one JSON object (``rows``: one per model and length). Example::

    python benchmarks/bench_sdn_flagsim.py --data runs/flagsim-cpu --out runs/sdn-bench \\
        --frames 10 20 30 40 50 60 --sdn-frames 30 60 --epochs 15
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from physinfer.datasets import ClipDataset
from physinfer.io import atomic_path, atomic_write_json
from physinfer_flag.sdn.baselines import SpectralPooling
from physinfer_flag.sdn.data import ArrayDataset, PreparedClips, SDNDataset, as_features
from physinfer_flag.sdn.evaluation import RegressionConfig, evaluate_triplets, evaluate_wind
from physinfer_flag.sdn.frontend import FrontEndConfig
from physinfer_flag.sdn.network import SDNConfig
from physinfer_flag.sdn.training import TrainConfig, train_sdn
from physinfer_flag.sdn.weights import load_sdn

SPLITS = ("train", "val", "test")


def cached_features(
    data: Path, split: str, config: FrontEndConfig, cache: Path, device: str | None
) -> SDNDataset:
    """A split's front-end features, computed once and memory-mapped afterwards.

    Args:
        data: Dataset directory.
        split: ``"train"``, ``"val"`` or ``"test"``.
        config: Front-end settings.
        cache: Directory of the cached arrays.
        device: Torch device of the front end.

    Returns:
        A ``"features"`` dataset ``(N, 4k, size/2, size/2)``.
    """
    clips = PreparedClips(ClipDataset(data, split), config=config)
    stem = cache / f"{config.n_frames}f-{config.size}px-{split}"
    array_path, meta_path = stem.with_suffix(".npy"), stem.with_suffix(".json")
    meta = {"frontend": dataclasses.asdict(config), "sim_ids": clips.sim_ids.tolist()}
    if not (
        array_path.is_file()
        and meta_path.is_file()
        and json.loads(meta_path.read_text()) == meta
    ):
        print(f"front end: {split}, {config.n_frames} frames", file=sys.stderr)
        features = as_features(clips, config, device=device, progress=True)
        cache.mkdir(parents=True, exist_ok=True)
        with atomic_path(array_path, suffix=".npy") as tmp:
            np.save(tmp, np.asarray(features.get_batch(np.arange(len(features)))))
        atomic_write_json(meta_path, meta)
    return ArrayDataset(
        inputs=np.load(array_path, mmap_mode="r", allow_pickle=False),
        sim_ids=clips.sim_ids,
        theta=clips.theta,
        theta_names=clips.theta_names,
        group_ids=clips.group_ids,
        kind="features",
        fps=config.fps,
        frontend_config=config,
    )


def scores_of(
    model: torch.nn.Module, splits: dict[str, SDNDataset], regression: RegressionConfig, device: str | None
) -> dict[str, Any]:
    """Test triplet accuracy and wind regression (head fitted on train) of an embedding."""
    triplets = evaluate_triplets(model, splits["test"], device=device)
    wind = evaluate_wind(model, splits["train"], splits["test"], config=regression, device=device)
    return {
        "triplet_accuracy": triplets["triplet_accuracy"],
        "n_triplets": triplets["n_triplets"],
        "mse": wind["mse"],
        "acc_at_0_5": wind["acc_at_0_5"],
        "n": wind["n"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="dataset directory")
    parser.add_argument("--out", type=Path, required=True, help="feature cache and SDN runs")
    parser.add_argument("--frames", type=int, nargs="+", default=[30], help="spectral baseline lengths")
    parser.add_argument("--sdn-frames", type=int, nargs="*", default=[30], help="lengths to train an SDN at")
    parser.add_argument("--epochs", type=int, default=15, help="SDN training epochs")
    parser.add_argument("--head-epochs", type=int, default=30, help="regression head epochs")
    parser.add_argument("--size", type=int, default=224)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--device", default=None)
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    regression = RegressionConfig(epochs=args.head_epochs)
    started = time.perf_counter()
    rows: list[dict[str, Any]] = []
    # The trained lengths first, in the order given: they matter most if the run is cut short.
    for n_frames in dict.fromkeys([*args.sdn_frames, *sorted(args.frames)]):
        frontend = dataclasses.replace(FrontEndConfig(), n_frames=n_frames, size=args.size)
        t0 = time.perf_counter()
        splits = {
            s: cached_features(args.data, s, frontend, args.out / "features", args.device) for s in SPLITS
        }
        frontend_s = time.perf_counter() - t0
        if n_frames in args.frames:
            t0 = time.perf_counter()
            spectral = scores_of(SpectralPooling(frontend=frontend), splits, regression, args.device)
            rows.append(
                {"model": "spectral", "frames": n_frames, **spectral,
                 "seconds": round(time.perf_counter() - t0, 1), "frontend_seconds": round(frontend_s, 1)}
            )  # fmt: skip
            print(json.dumps(rows[-1]), file=sys.stderr)
        if n_frames in args.sdn_frames:
            out = args.out / f"sdn-{n_frames}f"
            t0 = time.perf_counter()
            result = train_sdn(
                splits["train"],
                splits["val"],
                out_dir=out,
                model_config=SDNConfig(frontend=frontend),
                config=TrainConfig(epochs=args.epochs),
                device=args.device,
                info={"data": str(args.data.resolve()), "positives": "simulation"},
            )
            train_s = time.perf_counter() - t0
            sdn = scores_of(load_sdn(out, args.device), splits, regression, args.device)
            rows.append(
                {"model": "sdn", "frames": n_frames, **sdn, "best_epoch": result.best_epoch,
                 "val_triplet_accuracy": result.best["val_triplet_accuracy"],
                 "epochs": result.epochs_completed, "train_seconds": round(train_s, 1)}
            )  # fmt: skip
            print(json.dumps(rows[-1]), file=sys.stderr)
    print(
        json.dumps(
            {
                "data": str(args.data),
                "rows": rows,
                "epochs": args.epochs,
                "head_epochs": args.head_epochs,
                "seconds": round(time.perf_counter() - started, 1),
                "threads": torch.get_num_threads(),
            }
        )
    )


if __name__ == "__main__":
    main()
