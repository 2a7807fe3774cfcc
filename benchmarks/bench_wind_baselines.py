"""Wind-speed regression of the learned baselines (ResNet-18, CNN+LSTM) on a FlagSim set.

The paper's wind table compares the SDN with a multi-frame ResNet-18 (temporal average
pooling, 20 frames) and Yang et al.'s CNN+LSTM (10 frames), both trained from scratch with
their regression head. ``physinfer evaluate wind --embedder resnet18|cnn_lstm`` does exactly
that at 224 px, which costs 2-4 s per clip and training step on one CPU core (hours per
epoch). This script runs the same protocol — head and backbone trained on the ``train``
split, scored on the ``test`` split — with the knobs a CPU run needs: the input side
(``--size``), the epochs, and the threads. The clips are decoded and prepared once and held
in memory (uint8). One JSON object per model is written to ``--out`` as it finishes, so a
cut-short run keeps what it measured; the summary is printed on stdout. Example::

    python benchmarks/bench_wind_baselines.py --data runs/flagsim-cpu --models cnn_lstm \\
        --size 112 --epochs 5 --threads 1 --out runs/wind_baselines
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
from physinfer.io import atomic_write_json
from physinfer_flag.sdn.data import PreparedClips, SDNDataset, subset
from physinfer_flag.sdn.evaluation import RegressionConfig, evaluate_wind
from physinfer_flag.sdn.frontend import FrontEndConfig
from physinfer_flag.sdn.workflows import regression_backbone


def prepared_split(data: Path, split: str, config: FrontEndConfig) -> SDNDataset:
    """A split's clips, prepared (grayscale, resized, cut) once and held in memory."""
    clips = PreparedClips(ClipDataset(data, split), config=config)
    return subset(clips, np.arange(len(clips)))


def run_model(args: argparse.Namespace, name: str) -> dict[str, Any]:
    """Train one baseline with its head on ``train`` and score it on ``test``."""
    torch.manual_seed(args.seed)  # the baseline's initialisation
    size = dataclasses.replace(FrontEndConfig(), size=args.size)
    backbone, frontend = regression_backbone(name, args.frames, size, args.device)
    t0 = time.perf_counter()
    train, test = (prepared_split(args.data, s, frontend) for s in ("train", "test"))
    prepare_s = time.perf_counter() - t0
    config = RegressionConfig(epochs=args.epochs, finetune=True, seed=args.seed, progress=True)
    t0 = time.perf_counter()
    scores = evaluate_wind(backbone, train, test, config=config, device=args.device)
    return {
        "model": name,
        "frames": frontend.n_frames,
        "size": args.size,
        "epochs": args.epochs,
        "n_train": len(train),
        **scores,
        "train_seconds": round(time.perf_counter() - t0, 1),
        "prepare_seconds": round(prepare_s, 1),
        "threads": torch.get_num_threads(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="FlagSim dataset directory")
    parser.add_argument("--out", type=Path, required=True, help="directory of one JSON per model")
    parser.add_argument("--models", nargs="+", default=["resnet18", "cnn_lstm"], choices=["resnet18", "cnn_lstm"])
    parser.add_argument("--size", type=int, default=224, help="input side in px (224 in the paper)")
    parser.add_argument("--frames", type=int, default=None, help="input frames (default: 20 / 10, as the paper)")
    parser.add_argument("--epochs", type=int, default=30, help="epochs of backbone and head together")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--device", default=None)
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in args.models:
        row = run_model(args, name)
        atomic_write_json(args.out / f"{name}-{row['size']}px-{row['epochs']}ep.json", row)
        print(json.dumps(row), file=sys.stderr)
        rows.append(row)
    print(json.dumps({"data": str(args.data), "rows": rows}))


if __name__ == "__main__":
    main()
