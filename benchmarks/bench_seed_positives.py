"""How SDN embeddings treat other simulation seeds of the same θ (issue 5, positives rule).

On a dataset generated with ``--seeds-per-theta 2`` (or more), every θ of the chosen split
has several simulations that differ only in the simulator's seed — for the chaotic flag,
different realisations of the same physics, which is what a real target is to any
simulation. For each model (SDN weights, or ``spectral`` for the parameter-free pooling)
the split is embedded once and scored on the same triplets:

- ``same_simulation``: anchor, another render of the same simulation, a clip of another θ;
- ``across_seeds``: anchor, a render of another simulation of the same θ, a clip of
  another θ (the case refinement depends on: the target is never the simulation's
  realisation);

plus the median distances of the three kinds of pairs and ``seed_to_theta_ratio`` = median
distance across seeds / median distance to other θ (lower: the seed matters less compared
to θ). Negatives never share the anchor's θ, so the two accuracies differ only in the
positive. Prints one JSON object.

Usage::

    python benchmarks/bench_seed_positives.py --data runs/flagsim-cpu-s2 \\
        --model simulation=runs/sdn-s2-simulation/sdn.safetensors \\
        --model parameters=runs/sdn-s2-parameters/sdn.safetensors --model spectral=spectral
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from physinfer_flag.sdn.baselines import SpectralPooling
from physinfer_flag.sdn.data import group_ids_from_theta
from physinfer_flag.sdn.evaluation import embed_dataset
from physinfer_flag.sdn.frontend import FrontEndConfig
from physinfer_flag.sdn.weights import load_sdn
from physinfer_flag.sdn.workflows import open_split


def seed_triplets(sim_ids: np.ndarray, groups: np.ndarray, seed: int = 0) -> dict[str, np.ndarray]:
    """One triplet per anchor that has both kinds of positive, for each kind.

    Args:
        sim_ids: ``(N,)`` simulation of each clip.
        groups: ``(N,)`` θ group of each clip.
        seed: Seed of the draw.

    Returns:
        ``{"same_simulation": (M, 3), "across_seeds": (M, 3)}`` index triplets sharing
        anchors and negatives.
    """
    rng = np.random.default_rng(seed)
    rows: dict[str, list[tuple[int, int, int]]] = {"same_simulation": [], "across_seeds": []}
    for a in range(len(sim_ids)):
        same_sim = np.flatnonzero((sim_ids == sim_ids[a]) & (np.arange(len(sim_ids)) != a))
        other_seed = np.flatnonzero((groups == groups[a]) & (sim_ids != sim_ids[a]))
        other_theta = np.flatnonzero(groups != groups[a])
        if len(same_sim) == 0 or len(other_seed) == 0 or len(other_theta) == 0:
            continue
        negative = int(rng.choice(other_theta))
        rows["same_simulation"].append((a, int(rng.choice(same_sim)), negative))
        rows["across_seeds"].append((a, int(rng.choice(other_seed)), negative))
    return {k: np.asarray(v, dtype=np.int64).reshape(-1, 3) for k, v in rows.items()}


def pair_distances(embeddings: np.ndarray, sim_ids: np.ndarray, groups: np.ndarray) -> dict[str, float]:
    """Median Euclidean distance of same-simulation, same-θ-other-seed and other-θ pairs."""
    e = torch.from_numpy(embeddings).double()
    d = torch.cdist(e, e).numpy()
    upper = np.triu(np.ones_like(d, dtype=bool), k=1)
    same_sim = sim_ids[:, None] == sim_ids[None, :]
    same_theta = groups[:, None] == groups[None, :]
    medians = {
        "median_distance_same_simulation": float(np.median(d[upper & same_sim])),
        "median_distance_across_seeds": float(np.median(d[upper & same_theta & ~same_sim])),
        "median_distance_other_theta": float(np.median(d[upper & ~same_theta])),
    }
    medians["seed_to_theta_ratio"] = (
        medians["median_distance_across_seeds"] / medians["median_distance_other_theta"]
    )
    return medians


def accuracy(embeddings: np.ndarray, triplets: np.ndarray) -> float:
    """Share of triplets whose anchor is strictly closer to the positive than the negative."""
    a, p, n = (embeddings[triplets[:, i]] for i in range(3))
    return float(np.mean(np.linalg.norm(a - p, axis=1) < np.linalg.norm(a - n, axis=1)))


def score_model(data: Path, split: str, model: str, triplets: dict[str, np.ndarray]) -> dict[str, Any]:
    """Embed the split with one model and score it."""
    # The spectral pooling reads as many frames as the shipped SDN (60).
    network = SpectralPooling(frontend=FrontEndConfig(n_frames=60)) if model == "spectral" else load_sdn(model)
    dataset = open_split(data, split, network.frontend_config)  # type: ignore[arg-type]
    started = time.perf_counter()
    embeddings = embed_dataset(network, dataset)
    groups = group_ids_from_theta(dataset.theta)
    scores: dict[str, Any] = {f"{k}_accuracy": accuracy(embeddings, t) for k, t in triplets.items()}
    scores.update(pair_distances(embeddings, dataset.sim_ids, groups))
    scores["embed_s"] = time.perf_counter() - started
    return scores


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="dataset made with --seeds-per-theta >= 2")
    parser.add_argument("--split", default="test")
    parser.add_argument("--model", action="append", required=True,
                        help="NAME=WEIGHTS (an SDN file or training directory) or NAME=spectral; repeat")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument("--seed", type=int, default=0, help="seed of the triplet draw")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    from physinfer.datasets import ClipDataset

    clips = ClipDataset(args.data, args.split)
    groups = group_ids_from_theta(np.asarray(clips.params))
    triplets = seed_triplets(clips.sim_ids, groups, seed=args.seed)
    if len(triplets["across_seeds"]) == 0:
        raise SystemExit(f"{args.data} has no θ with two simulations in {args.split}: generate it with "
                         "--seeds-per-theta 2 or more")
    models = dict(item.split("=", 1) for item in args.model)
    report = {
        "benchmark": "seed_positives",
        "data": str(args.data),
        "split": args.split,
        "n_clips": len(clips),
        "n_simulations": int(len(np.unique(clips.sim_ids))),
        "n_theta": int(len(np.unique(groups))),
        "n_triplets": int(len(triplets["across_seeds"])),
        "models": {name: {"weights": path, **score_model(args.data, args.split, path, triplets)}
                   for name, path in models.items()},
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, {platform.system()}",
    }
    print(json.dumps(report))


if __name__ == "__main__":
    main()
