"""Fit the flag's render-parameter estimator (ζ from the SDN embedding) on a generated dataset.

Reads a dataset made by ``physinfer dataset generate`` whose ``train`` and ``test`` splits
were embedded by ``posterior train``/``evaluate calibration`` (``DATASET/embeddings/*.npz``,
rows in manifest order), fits :func:`physinfer.render_estimate.fit_render_estimator` on the
train split, measures its error on the test split and writes the estimator file.

    nice -n 10 .venv/bin/python benchmarks/make_render_estimator.py --data runs/flag-posterior \
        --out plugins/flag/physinfer_flag/data/render_estimator_default.npz

Prints one JSON object: per component the held-out rms error, the spread of ζ, R² and the
share of held-out clips inside the 90 % interval.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from physinfer.plugins import load_registry
from physinfer.posterior.fingerprint import embedder_probe
from physinfer.render_estimate import Z90, fit_render_estimator

#: The ζ components the SDN embedding is sensitive to (benchmarks/bench_zeta_sensitivity.py).
COMPONENTS = ("framing", "camera_azimuth_deg", "camera_elevation_deg")


def split_data(data: Path, split: str) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """``(N, E)`` cached embeddings of ``split`` and ``{name: (N,)}`` ζ from the manifest."""
    rows = [
        json.loads(line)
        for line in (data / "manifest.jsonl").read_text().splitlines()
        if line.strip()
    ]
    rows = [r for r in rows if r["split"] == split]
    caches = sorted((data / "embeddings").glob(f"*-{split}.npz"))
    if len(caches) != 1:
        raise SystemExit(
            f"expected one embeddings cache of {split} in {data}/embeddings, found {len(caches)}"
        )
    with np.load(caches[0], allow_pickle=False) as d:
        x = d["x"]
    if len(x) != len(rows):
        raise SystemExit(f"{caches[0]} holds {len(x)} embeddings for {len(rows)} {split} clips")
    return x, {k: np.array([r["render_params"][k] for r in rows], dtype=float) for k in COMPONENTS}


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--data", type=Path, default=Path("runs/flag-posterior"))
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("plugins/flag/physinfer_flag/data/render_estimator_default.npz"),
    )
    args = parser.parse_args()
    x_train, z_train = split_data(args.data, "train")
    x_test, z_test = split_data(args.data, "test")
    registry, _ = load_registry()
    embedder = registry.embedder("sdn", model=None, device="cpu")
    estimator = fit_render_estimator(
        x_train, z_train, x_test, z_test, embedder="sdn", probe=embedder_probe(embedder)
    )
    estimator.save(args.out)
    report = {}
    for k, name in enumerate(estimator.names):
        pred = np.array([estimator.predict(x)[k] for x in x_test])
        err = pred - z_test[name]
        report[name] = {
            "rmse": float(np.sqrt(np.mean(err**2))),
            "prior_sd": float(estimator.prior_sd[k]),
            "r2": float(1 - np.mean(err**2) / np.var(z_test[name])),
            "coverage90": float(np.mean(np.abs(err) <= Z90 * estimator.sd[k])),
        }
    print(
        json.dumps(
            {
                "estimator": str(args.out),
                "train": len(x_train),
                "test": len(x_test),
                "components": report,
            }
        )
    )


if __name__ == "__main__":
    main()
