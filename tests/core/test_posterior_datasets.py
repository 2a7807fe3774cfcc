"""``posterior train`` on several datasets at once (``--data A --data B``): the pairs of both,
each embedded into its own cache, checked on the held-out clips; datasets generated otherwise
are refused before anything is embedded (two small generated pendulum datasets, no mocks)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from physinfer.errors import UserInputError


def _generate(physinfer_cli, root: Path, sims: str, seed: int) -> Path:
    proc = physinfer_cli(
        "dataset", "generate", "--plugin", "pendulum_lab", "--sims", sims, "--renders-per-sim", "1",
        "--frames", "50", "--size", "48", "--workers", "0", "--seed", str(seed), "--out", str(root), "--json",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    return root


@pytest.fixture(scope="module")
def two_sets(tmp_path_factory, physinfer_cli) -> tuple[Path, Path]:
    """30 training + 20 test simulations, and 30 more training ones of another seed: each
    alone too few to train on (50), together enough."""
    base = tmp_path_factory.mktemp("posterior-datasets")
    first = _generate(physinfer_cli, base / "first", "30,0,20", seed=5)
    second = _generate(physinfer_cli, base / "second", "30,0,0", seed=6)
    return first, second


def _train(physinfer_cli, out: Path, *data: Path):
    args = [a for d in data for a in ("--data", str(d))]
    return physinfer_cli(
        "posterior", "train", "--plugin", "pendulum_lab", *args, "--out", str(out),
        "--embedder-frames", "50", "--max-epochs", "5", "--device", "cpu", "--json",
        "--stored", "--accept-miscalibrated",  # a small estimator: its calibration is not the point
    )  # fmt: skip


def test_training_on_two_datasets_uses_the_clips_of_both_each_cached_beside_its_dataset(
    two_sets, physinfer_cli, tmp_path
):
    first, second = two_sets
    alone = _train(physinfer_cli, tmp_path / "alone.safetensors", first)
    assert alone.returncode == 2 and "30 training clips are too few" in alone.json()["error"]

    summary = _train(physinfer_cli, tmp_path / "both.safetensors", first, second).json()
    assert summary["training"]["pairs"] == 60
    assert summary["training"]["dataset"] == ["first", "second"]
    caches = [Path(c) for c in summary["embeddings_cache"]]
    assert [c.parent.parent for c in caches] == [first, second]
    for cache in caches:
        with np.load(cache, allow_pickle=False) as data:
            assert data["x"].shape[0] == 30
    # checked on the held-out clips there are: the first dataset's 20 test clips
    assert summary["held_out"]["split"] == "test" and summary["held_out"]["clips"] == 20


def test_the_api_takes_several_datasets_and_refuses_a_wrong_one_naming_it(two_sets, tmp_path):
    import physinfer.api as pi

    first, second = two_sets
    trained = pi.train_posterior(
        "pendulum_lab", data=(first, str(second)), out=tmp_path / "api.safetensors", embedder_frames=50,
        max_epochs=5, device="cpu", stored=True, accept_miscalibrated=True,
    )  # fmt: skip
    assert trained.to_dict()["training"]["pairs"] == 60 and len(trained.caches) == 2
    with pytest.raises(UserInputError, match="--data 3: give a path"):
        pi.train_posterior("pendulum_lab", data=(first, 3), out=tmp_path / "e.safetensors")
    with pytest.raises(UserInputError, match="data: give"):
        pi.train_posterior("pendulum_lab", data=(), out=tmp_path / "e.safetensors")


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (lambda config: config["preset"]["clip"].update(height=64, width=64), "its clip format"),
        (lambda config: config["parameters"][0]["bounds"].__setitem__(1, 5.0), "its parameters"),
        (lambda config: config.update(phenomenon="flag"), "generated for --plugin flag"),
    ],
)
def test_datasets_generated_otherwise_are_refused_before_anything_is_embedded(
    two_sets, physinfer_cli, tmp_path, edit, words
):
    first, second = two_sets
    other = tmp_path / "other"
    shutil.copytree(second, other, ignore=shutil.ignore_patterns("embeddings"))
    info = json.loads((other / "dataset.json").read_text())
    edit(info["config"])
    (other / "dataset.json").write_text(json.dumps(info))
    proc = _train(physinfer_cli, tmp_path / "mixed.safetensors", first, other)
    assert proc.returncode == 2, proc.stderr[-1500:]
    assert words in proc.json()["error"]
    assert not (other / "embeddings").exists() and not (tmp_path / "mixed.safetensors").exists()
