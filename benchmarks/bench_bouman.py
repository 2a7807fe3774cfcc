"""Bouman et al. evaluation on the synthetic 90-video hanging-cloth set, per embedder.

Generates the synthetic dataset (30 fabrics × W1–W3, 60 frames, 224 px, seed 0; the
``physinfer dataset bouman`` defaults) into ``--data`` unless it is already there, then
for each embedder runs the paper's protocol — embeddings → PCA to 50 dimensions fitted in
each fold → linear regression, leaving one fabric out → Pearson R on log values — and
prints one JSON object:

- ``results``: per embedder ``pearson_stiffness``, ``pearson_area_weight``, ``n_videos``,
  ``n_fabrics``, ``pca_dims``, ``embed_s`` (seconds to embed all videos); or ``skipped``
  with the reason (e.g. the SDN's shipped weights are missing);
- ``generate_s``: seconds spent generating (0 when the data existed);
- ``load_before`` / ``load_after``: 1-minute load average (the cores are shared).

Usage: ``python benchmarks/bench_bouman.py [--data DIR] [--embedders spectral,sdn] [--device cpu]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

from physinfer.errors import UserInputError
from physinfer.plugins import load_registry
from physinfer_hanging_cloth.data import load_dataset
from physinfer_hanging_cloth.evaluation import embed_videos, evaluate_embeddings
from physinfer_hanging_cloth.generate import SyntheticSettings, generate_dataset


def main() -> None:
    """Parse arguments, generate if needed, evaluate each embedder, print one JSON object."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("/tmp/physinfer-bouman-synthetic"))
    parser.add_argument("--embedders", default="spectral,sdn")
    parser.add_argument("--device", default=None)
    parser.add_argument("--pca-dims", type=int, default=50)
    args = parser.parse_args()

    load_before = os.getloadavg()[0]
    started = time.perf_counter()
    generated = generate_dataset(
        args.data, SyntheticSettings(), on_video=lambda d, n: print(f"fabric {d}/{n}", file=sys.stderr)
    )
    generate_s = time.perf_counter() - started if generated["written"] else 0.0
    dataset = load_dataset(args.data)
    registry, _ = load_registry()
    results: dict[str, dict] = {}
    for name in [n.strip() for n in args.embedders.split(",") if n.strip()]:
        try:
            embedder = registry.embedder(name, model=None, device=args.device)
        except UserInputError as exc:
            results[name] = {"skipped": str(exc)}
            continue
        t0 = time.perf_counter()
        embeddings = embed_videos(dataset, embedder)
        embed_s = time.perf_counter() - t0
        result = evaluate_embeddings(dataset, embeddings, pca_dims=args.pca_dims)
        results[name] = {**result.summary(), "embed_s": embed_s}
        print(f"{name}: {results[name]}", file=sys.stderr)
    print(
        json.dumps(
            {
                "data": str(args.data),
                "n_videos": len(dataset.videos),
                "n_fabrics": dataset.n_fabrics,
                "generate_s": generate_s,
                "results": results,
                "machine": f"{platform.machine()} {os.cpu_count()} CPUs",
                "load_before": load_before,
                "load_after": os.getloadavg()[0],
            }
        )
    )


if __name__ == "__main__":
    main()
