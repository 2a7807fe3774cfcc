"""Seconds per SDN training epoch on a device: ``train_sdn`` with the paper's network and
settings, two epochs over synthetic 60-frame 224-px grating clips (the shape of
``make pretrained``'s inputs; :func:`physinfer_flag.sdn.synthetic.grating_dataset`, four
renders of each θ). The first epoch's start-up is included.

    python benchmarks/bench_sdn_training.py --device cuda --thetas 128
    python benchmarks/bench_sdn_training.py --device cpu --thetas 16 --threads 2

Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time

import torch


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    parser.add_argument("--thetas", type=int, default=16, help="four clips each")
    parser.add_argument("--threads", type=int, default=None, help="torch threads on the CPU")
    parser.add_argument("--epochs", type=int, default=2)
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    from physinfer_flag.sdn.synthetic import grating_dataset
    from physinfer_flag.sdn.training import TrainConfig, train_sdn

    clips = grating_dataset(n_thetas=args.thetas, renders_per_sim=4, n_frames=60, size=224)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench-sdn-training-") as folder:
        train_sdn(clips, None, out_dir=folder, config=TrainConfig(epochs=args.epochs, progress=False), device=args.device)
    seconds = (time.perf_counter() - started) / args.epochs
    print(json.dumps({
        "benchmark": "sdn_training", "device": args.device, "clips": len(clips.inputs),
        "seconds_per_epoch": round(seconds, 2), "ms_per_clip": round(1000 * seconds / len(clips.inputs), 1),
        "threads": torch.get_num_threads(), "gpu": torch.cuda.get_device_name(0) if args.device.startswith("cuda") else None,
        "platform": platform.platform(), "date": time.strftime("%Y-%m-%d"),
    }, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
