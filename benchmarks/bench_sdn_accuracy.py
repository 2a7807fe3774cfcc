"""Accuracy tables of the SDN on a generated dataset (the paper's Tables 2 and 3).

Trains one SDN per input length (``--frames``, the paper's frames table extended to
longer clips) and per positive rule (``--positives``), scores triplet accuracy on the
test split, and the wind-speed regression (MSE, Acc@0.5) of each trained SDN and of the
baselines (``--baselines``: spectral, resnet18, cnn_lstm). Prints one JSON object.

Needs a dataset directory written by ``physinfer dataset generate --plugin flag``; its
clips must hold at least as many frames as the longest ``--frames``.

Example (CPU-sized)::

    python benchmarks/bench_sdn_accuracy.py --data data/flagsim-cpu --out runs/sdn-acc \\
        --frames 10 20 30 40 50 --epochs 30 --baselines spectral
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import torch

from physinfer_flag.sdn.evaluation import RegressionConfig
from physinfer_flag.sdn.frontend import FrontEndConfig
from physinfer_flag.sdn.network import SDNConfig
from physinfer_flag.sdn.training import TrainConfig
from physinfer_flag.sdn.workflows import (
    evaluate_triplets_in_directory,
    evaluate_wind_in_directory,
    train_from_directory,
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="dataset directory")
    parser.add_argument(
        "--out", type=Path, required=True, help="where trained networks go (resumable)"
    )
    parser.add_argument("--frames", type=int, nargs="+", default=[30])
    parser.add_argument(
        "--positives", nargs="+", default=["simulation"], choices=["simulation", "theta"]
    )
    parser.add_argument(
        "--baselines", nargs="*", default=["spectral"], choices=["spectral", "resnet18", "cnn_lstm"]
    )
    parser.add_argument("--epochs", type=int, default=30)
    parser.add_argument(
        "--head-epochs", type=int, default=30, help="epochs of the regression heads"
    )
    parser.add_argument("--size", type=int, default=224, help="input side (224 in the paper)")
    parser.add_argument("--target", default="wind_speed")
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--device", default=None)
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    regression = RegressionConfig(target=args.target, epochs=args.head_epochs)
    started = time.perf_counter()
    rows = []
    for positives in args.positives:
        for n_frames in args.frames:
            frontend = dataclasses.replace(FrontEndConfig(), n_frames=n_frames, size=args.size)
            out = args.out / f"sdn-{positives}-{n_frames}f"
            print(f"training {out.name}", file=sys.stderr)
            summary = train_from_directory(
                args.data,
                out,
                positives=positives,
                model_config=SDNConfig(frontend=frontend),
                train_config=TrainConfig(epochs=args.epochs),
                device=args.device,
            )
            triplets = evaluate_triplets_in_directory(
                args.data, out, positives="simulation", device=args.device
            )
            wind = evaluate_wind_in_directory(args.data, out, config=regression, device=args.device)
            rows.append(
                {
                    "model": "sdn",
                    "positives": positives,
                    "frames": n_frames,
                    "triplet_accuracy": triplets["triplet_accuracy"],
                    "n_triplets": triplets["n_triplets"],
                    "mse": wind["mse"],
                    "acc_at_0_5": wind["acc_at_0_5"],
                    "n": wind["n"],
                    "best_epoch": summary["best_epoch"],
                    "val_triplet_accuracy": summary["best"]["val_triplet_accuracy"],
                }
            )
    for name in args.baselines:
        print(f"regression baseline {name}", file=sys.stderr)
        spectral = dataclasses.replace(FrontEndConfig(), size=args.size)
        wind = evaluate_wind_in_directory(
            args.data, name, config=regression, spectral_frontend=spectral, device=args.device
        )
        rows.append(
            {"model": name, "mse": wind["mse"], "acc_at_0_5": wind["acc_at_0_5"], "n": wind["n"]}
        )
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
