"""A dataset's manifest and its embeddings cache are data, not trusted code (issue 45): a θ
outside the parameter bounds, a clip file outside the dataset, or an edited embeddings cache
is refused or recomputed, never learnt from."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from physinfer.datasets.loader import ClipDataset
from physinfer.errors import UserInputError


@pytest.fixture(scope="module")
def small_set(tmp_path_factory, physinfer_cli) -> Path:
    root = tmp_path_factory.mktemp("untrusted") / "set"
    ran = physinfer_cli(
        "dataset", "generate", "--plugin", "pendulum_lab", "--sims", "4,0,2", "--frames", "20", "--size", "32",
        "--workers", "0", "--out", root, "--json",
    )  # fmt: skip
    assert ran.returncode == 0, ran.stderr[-2000:]
    return root


def _poisoned(small_set: Path, tmp_path: Path, row: int, **changes) -> Path:
    import shutil

    root = tmp_path / "poisoned"
    shutil.copytree(small_set, root)
    manifest = root / "manifest.jsonl"
    lines = manifest.read_text().splitlines()
    entry = json.loads(lines[row - 1])
    for key, value in changes.items():
        if key in entry.get("params", {}):
            entry["params"][key] = value
        else:
            entry[key] = value
    lines[row - 1] = json.dumps(entry)
    manifest.write_text("\n".join(lines) + "\n")
    return root


def test_a_manifest_theta_outside_the_bounds_is_refused_naming_the_row(small_set, tmp_path, physinfer_cli):
    root = _poisoned(small_set, tmp_path, 2, length=1e9)
    with pytest.raises(UserInputError, match=r"row 2 .*length=1000000000.0, outside its bounds"):
        ClipDataset(root, "train")
    ran = physinfer_cli("posterior", "train", "--plugin", "pendulum_lab", "--data", root,
                        "--out", tmp_path / "e.safetensors", "--json")  # fmt: skip
    assert ran.returncode == 2 and "row 2" in ran.json()["error"] and "length" in ran.json()["error"]
    assert not (tmp_path / "e.safetensors").exists()
    for bad in (float("nan"), "0.5", None):
        root = _poisoned(small_set, tmp_path / str(bad), 1, length=bad)
        with pytest.raises(UserInputError, match="row 1"):
            ClipDataset(root, None)


@pytest.mark.parametrize("name", ["../../../etc/passwd", "/etc/passwd", "shards/../../outside.npy"])
@pytest.mark.parametrize("key", ["file", "trajectory"])
def test_a_manifest_file_outside_the_dataset_is_refused(small_set, tmp_path, name, key, physinfer_cli):
    root = _poisoned(small_set, tmp_path, 1, **{key: name})
    with pytest.raises(UserInputError, match=f"row 1 names {key} .*outside"):
        ClipDataset(root, "train")
    ran = physinfer_cli("posterior", "train", "--plugin", "pendulum_lab", "--data", root,
                        "--out", tmp_path / "e.safetensors", "--json")  # fmt: skip
    assert ran.returncode == 2 and "outside" in ran.json()["error"]


class _CountingEmbedder:
    """A stand-in embedder: the mean of each clip's frames, counting the clips it embeds."""

    def __init__(self) -> None:
        self.embedded = 0

    def embed_many(self, clips):
        self.embedded += len(clips)
        return np.array([[c.frames.mean(), c.frames.std(), 1.0] for c in clips], dtype=np.float32)


def test_a_poisoned_embeddings_cache_is_not_trusted(small_set, tmp_path):
    import shutil

    from physinfer.posterior.features import embed_dataset

    root = tmp_path / "set"
    shutil.copytree(small_set, root)
    n = len(ClipDataset(root, "train"))
    first = _CountingEmbedder()
    pairs = embed_dataset(root, "train", first, {"embedder": "counting"})
    assert first.embedded == n and pairs.cache.is_file()
    again = _CountingEmbedder()
    assert np.array_equal(embed_dataset(root, "train", again, {"embedder": "counting"}).x, pairs.x)
    assert again.embedded == 0  # an intact cache is reused

    with np.load(pairs.cache, allow_pickle=False) as data:
        saved = {name: data[name] for name in data.files}
    np.savez(pairs.cache, **{**saved, "x": np.zeros_like(saved["x"])})  # all zeros under the same key
    third = _CountingEmbedder()
    redone = embed_dataset(root, "train", third, {"embedder": "counting"})
    assert third.embedded == n and np.array_equal(redone.x, pairs.x)

    x = saved["x"].copy()
    x[2] = 0.0  # one row edited: it and the rows after it are embedded again
    np.savez(pairs.cache, **{**saved, "x": x})
    fourth = _CountingEmbedder()
    assert np.array_equal(embed_dataset(root, "train", fourth, {"embedder": "counting"}).x, pairs.x)
    assert fourth.embedded == n - 2

    np.savez(pairs.cache, x=np.zeros_like(saved["x"]), key=saved["key"])  # a cache without digests
    fifth = _CountingEmbedder()
    assert np.array_equal(embed_dataset(root, "train", fifth, {"embedder": "counting"}).x, pairs.x)
    assert fifth.embedded == n
