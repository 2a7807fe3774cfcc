"""The (θ, embedding) pairs a posterior estimator learns from, cached beside the dataset.

A dataset made by ``physinfer dataset generate`` stores clips and the θ each was simulated
at. Training an estimator needs each clip's embedding ``s(x)``; embedding is the slow part
(seconds per clip for the flag's front end), so it is done once per (embedder, frames,
weights, dataset) and kept in ``DATASET/embeddings/<key>-<split>.npz``. An interrupted
embedding resumes from its last saved chunk (``.partial.npz``). Each cached embedding is
stored with a digest of its bytes together with its clip's identity (shard checksum, size,
index) and the cache key: a row whose digest does not match — an edited, zeroed or foreign
cache under the same name — is embedded again rather than trusted.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.as_given import as_given as through_user_path
from physinfer.datasets.loader import ClipDataset
from physinfer.datasets.storage import MANIFEST_FILE, file_digest
from physinfer.errors import UserInputError
from physinfer.io import atomic_save_npz
from physinfer.parameters import ParameterSpace
from physinfer.posterior.inputs import render_context
from physinfer.roles import Embedder
from physinfer.scene import scene_context
from physinfer.types import Clip

CACHE_DIR = "embeddings"
#: Clips embedded between two saves of a partial cache.
CHUNK = 32


@dataclass(frozen=True)
class EmbeddedSet:
    """The embedded clips of one dataset split.

    Attributes:
        parameter_space: The space θ was drawn from (the dataset's).
        theta_unit: ``(N, D)`` float32 θ normalised to ``[-1, 1]``.
        x: ``(N, E)`` float32 embeddings.
        sim_ids: ``(N,)`` simulation id of each clip.
        cache: The cache file the pairs came from (or were written to).
        scene_ranges: The scene settings the dataset varied (``--scene-range``), or ``{}``.
        context: ``(N, C)`` float32 those settings of each clip
            (:func:`physinfer.scene.scene_context`; ``C`` = 0 without ranges).
        as_given: How the clips reached the embedder (the target path's identity), or ``None``.
        render_params: ζ of each clip (the dataset's record), or empty.
        render_inputs: ``{name: [low, high]}``: the render settings the estimator is told,
            appended to the conditions after the scene context
            (:func:`physinfer.posterior.inputs.render_context`); empty: none
            (:meth:`with_render_inputs` sets them).
    """

    parameter_space: ParameterSpace
    theta_unit: np.ndarray
    x: np.ndarray
    sim_ids: np.ndarray
    cache: Path
    scene_ranges: dict[str, list[float]] = field(default_factory=dict)
    context: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=np.float32))
    as_given: dict[str, Any] | None = None
    render_params: tuple[Mapping[str, Any], ...] = ()
    render_inputs: Mapping[str, list[float]] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.x.shape[0])

    @property
    def conditions(self) -> np.ndarray:
        """``(N, E + C + R)`` what the estimator is conditioned on: the embedding, then the
        ranged scene settings, then the told render settings (a dataset of one scene and an
        estimator told nothing: the embedding alone)."""
        parts = [self.x]
        if self.context.size:
            parts.append(self.context)
        if self.render_inputs:
            told = [render_context(self.render_inputs, zeta) for zeta in self.render_params]
            parts.append(np.asarray(told, dtype=np.float32).reshape(len(self), len(self.render_inputs)))
        if len(parts) == 1:
            return self.x
        return np.concatenate(parts, axis=1).astype(np.float32)

    def with_render_inputs(self, ranges: Mapping[str, list[float]] | None) -> EmbeddedSet:
        """These pairs conditioned on the clips' render settings ``ranges`` too (``None``
        or empty: as they are).

        Raises:
            UserInputError: the clips' ζ were not recorded, or lack a setting.
        """
        if not ranges:
            return self
        missing = sorted({name for name in ranges for zeta in self.render_params if name not in zeta})
        if len(self.render_params) != len(self) or missing:
            raise UserInputError(
                f"the clips of {_root(self)} do not record the render settings "
                f"{', '.join(missing or sorted(ranges))} the estimator takes; use a dataset made by "
                "`physinfer dataset generate`"
            )
        return replace(self, render_inputs={k: list(v) for k, v in sorted(ranges.items())})

    @property
    def theta(self) -> np.ndarray:
        """``(N, D)`` θ in physical units."""
        return np.stack(
            [spec.from_unit(self.theta_unit[:, i]) for i, spec in enumerate(self.parameter_space)], axis=1
        )


def join_sets(sets: Sequence[EmbeddedSet]) -> EmbeddedSet:
    """The embedded clips of several datasets as one training set (``posterior train`` with
    more than one ``--data``); its ``cache`` is the first set's. The caller has checked that
    the datasets agree (:func:`physinfer.posterior.train_workflow` refuses any that differ in
    clip format, parameters or scene before embedding them)."""
    if len(sets) == 1:
        return sets[0]
    return replace(
        sets[0],
        theta_unit=np.concatenate([s.theta_unit for s in sets]),
        x=np.concatenate([s.x for s in sets]),
        sim_ids=np.concatenate([s.sim_ids for s in sets]),
        context=np.concatenate([s.context for s in sets]),
        render_params=tuple(zeta for s in sets for zeta in s.render_params),
    )


def _root(pairs: EmbeddedSet) -> Path:
    """The dataset directory ``pairs`` were embedded from (its cache lies in ``embeddings/``)."""
    return pairs.cache.parent.parent


@dataclass(frozen=True)
class TargetPath:
    """Clips embedded as users give them: :func:`physinfer.as_given.as_given` with this
    camera model, the per-clip effects drawn from ``seed``."""

    phenomenon: Any
    camera: Any  # physinfer.as_given.CameraModel
    seed: int = 0

    def identity(self) -> dict[str, Any]:
        return {"camera": self.camera.to_dict(), "seed": int(self.seed)}


def cache_key(
    dataset: ClipDataset, embedder_info: Mapping[str, Any], as_given: Mapping[str, Any] | None = None
) -> str:
    """A short hash naming what the cached embeddings depend on: the dataset's manifest,
    the embedder's identity (name, frames, weights digest) and the target path, if any."""
    ident: dict[str, Any] = {"manifest": file_digest(dataset.root / MANIFEST_FILE), "embedder": dict(embedder_info)}
    if as_given is not None:
        ident["as_given"] = dict(as_given)
    return hashlib.sha256(json.dumps(ident, sort_keys=True).encode()).hexdigest()[:16]


def embed_dataset(
    root: str | Path,
    split: str,
    embedder: Embedder,
    embedder_info: Mapping[str, Any],
    *,
    on_progress: Callable[[int, int], None] | None = None,
    as_given: TargetPath | None = None,
) -> EmbeddedSet:
    """Embed every clip of ``split`` (or read the cache), resuming a partial cache.

    Args:
        root: Dataset directory.
        split: ``"train"``, ``"val"`` or ``"test"``.
        embedder: The embedder the estimator will use at inference.
        embedder_info: JSON-ready identity of ``embedder`` (name, frames, weights digest):
            a different identity gets its own cache file.
        on_progress: Called as ``(done, total)`` after each chunk.
        as_given: Embed the clips as users give them (see the module), or ``None``: as stored.

    Raises:
        UserInputError: an empty split, or clips whose embedding is not finite.
    """
    dataset = ClipDataset(root, split)
    if len(dataset) == 0:
        raise UserInputError(
            f"split {split!r} of {dataset.root} holds no clips; generate it with --sims TRAIN,VAL,TEST"
        )
    key = cache_key(dataset, embedder_info, as_given.identity() if as_given else None)
    final = dataset.root / CACHE_DIR / f"{key}-{split}.npz"
    partial = final.with_suffix(".partial.npz")
    clip_ids = _clip_identities(dataset)
    done_x = _read_cached(final if final.is_file() else partial, key, clip_ids)
    total = len(dataset)
    if len(done_x) < total:
        parts = [done_x] if len(done_x) else []
        done = len(done_x)
        while done < total:
            stop = min(done + CHUNK, total)
            parts.append(_embed_range(dataset, embedder, done, stop, as_given, split))
            done = stop
            x = np.concatenate(parts)
            atomic_save_npz(
                final if done == total else partial,
                x=x,
                key=np.array(key),
                digests=np.array(_row_digests(key, clip_ids[: len(x)], x)),
            )
            if on_progress is not None:
                on_progress(done, total)
        partial.unlink(missing_ok=True)
        done_x = x
    elif on_progress is not None:
        on_progress(total, total)
    return EmbeddedSet(
        dataset.parameter_space,
        dataset.params_unit.astype(np.float32),
        done_x,
        dataset.sim_ids.copy(),
        final,
        dict(dataset.scene_ranges),
        _scene_context(dataset),
        as_given.identity() if as_given else None,
        tuple(row.get("render_params") or {} for row in dataset.rows),
    )


def _scene_context(dataset: ClipDataset) -> np.ndarray:
    """``(N, C)`` the ranged scene settings of each clip (``(N, 0)`` without ranges)."""
    if not dataset.scene_ranges:
        return np.zeros((len(dataset), 0), dtype=np.float32)
    return np.array(
        [scene_context(dataset.scene_ranges, scene) for scene in dataset.scenes], dtype=np.float32
    ).reshape(len(dataset), len(dataset.scene_ranges))


def _clip_identities(dataset: ClipDataset) -> list[str]:
    """What each clip's cached embedding is bound to: its shard's recorded checksum, the
    shard's size on disk and the clip's place in it (a regenerated or truncated shard
    changes it)."""
    sizes: dict[str, int] = {}
    ids = []
    for row in dataset.rows:
        file = str(row["file"])
        if file not in sizes:
            path = dataset.root / file
            sizes[file] = path.stat().st_size if path.is_file() else -1
        ids.append(f"{file}|{row['index']}|{row.get('checksum')}|{sizes[file]}")
    return ids


def _row_digests(key: str, clip_ids: list[str], x: np.ndarray) -> list[str]:
    """``(N,)`` sha256 of each embedding's bytes together with the cache key and its clip."""
    x = np.ascontiguousarray(x, dtype=np.float32)
    return [
        hashlib.sha256(f"{key}|{clip_id}|{x.shape[1]}|".encode() + x[i].tobytes()).hexdigest()
        for i, clip_id in enumerate(clip_ids)
    ]


def _read_cached(path: Path, key: str, clip_ids: list[str]) -> np.ndarray:
    """The leading embeddings saved in ``path`` whose digests match (none when it does not
    exist, is damaged, or carries no digests): a row that does not match its digest — an
    edited or zeroed cache — and every row after it are embedded again."""
    empty = np.zeros((0, 0), dtype=np.float32)
    if not path.is_file():
        return empty
    try:
        with np.load(path, allow_pickle=False) as data:
            x = np.asarray(data["x"], dtype=np.float32)
            stored = [str(d) for d in np.asarray(data["digests"]).reshape(-1)]
    except (OSError, ValueError, KeyError, EOFError):
        return empty  # re-embed rather than trust a damaged file or one without digests
    if x.ndim != 2 or len(x) > len(clip_ids) or len(stored) != len(x) or not np.isfinite(x).all():
        return empty
    expected = _row_digests(key, clip_ids[: len(x)], x)
    good = 0
    while good < len(x) and stored[good] == expected[good]:
        good += 1
    return x[:good] if good else empty


SPLIT_CODES = {"train": 0, "val": 1, "test": 2}


def _embed_range(
    dataset: ClipDataset,
    embedder: Embedder,
    start: int,
    stop: int,
    as_given: TargetPath | None = None,
    split: str = "train",
) -> np.ndarray:
    clips = [as_clip(dataset[i], dataset.fps) for i in range(start, stop)]
    if as_given is not None:
        clips = [
            through_user_path(
                clip,
                phenomenon=as_given.phenomenon,
                embedder=embedder,
                model=as_given.camera,
                rng=np.random.default_rng([as_given.seed, SPLIT_CODES.get(split, 3), start + k]),
            )
            for k, clip in enumerate(clips)
        ]
    x = np.asarray(embedder.embed_many(clips), dtype=np.float32)
    bad = ~np.isfinite(x).all(axis=1)
    if bad.any():
        first = start + int(np.flatnonzero(bad)[0])
        raise UserInputError(
            f"the embedding of clip {first} of {dataset.root} is not finite; the clip may be blank or "
            "damaged (re-generate the dataset) or the embedder unsuited to it"
        )
    return x


def as_clip(frames: np.ndarray, fps: float) -> Clip:
    """A stored ``(T, H, W)`` or ``(T, H, W, 3)`` uint8 clip as a :class:`Clip`."""
    frames = np.asarray(frames)
    if frames.ndim == 3:
        frames = frames[..., None]
    return Clip(frames, fps)
