"""Reading a generated dataset for training: :class:`ClipDataset`.

Shards are opened memory-mapped (``np.load(mmap_mode="r")``), so a dataset larger
than memory costs only the pages a training loop touches. Labels come as arrays in
render order: simulation ids (positives share one), θ in physical units and
normalised to ``[-1, 1]``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.datasets.presets import SPLITS, ClipFormat
from physinfer.datasets.storage import DATASET_FILE, MANIFEST_FILE, read_json, read_manifest
from physinfer.errors import UserInputError
from physinfer.parameters import ParameterSpace
from physinfer.types import Trajectory


class ClipDataset(Sequence[np.ndarray]):
    """The clips of one split (or all) of a dataset directory.

    ``dataset[i]`` is clip ``i`` as a read-only memory-mapped uint8 array of shape
    ``(T, H, W)`` (grayscale) or ``(T, H, W, 3)`` (RGB).

    Args:
        root: Dataset directory written by ``physinfer dataset generate``.
        split: ``"train"``, ``"val"``, ``"test"``, or ``None`` for all renders.

    Attributes:
        root: The directory.
        split: The split.
        info: The parsed ``dataset.json``.
        clip_format: Stored clip format (``n_frames``, ``fps``, size, channels).
        parameter_space: The space θ was drawn from.
        param_names: ``(D,)`` names of the columns of :attr:`params`.
        rows: The manifest rows of this split, in render order.
        sim_ids: ``(N,)`` int64 simulation id of each clip.
        render_ids: ``(N,)`` int64 global render id of each clip.
        params: ``(N, D)`` float64 θ of each clip, physical units.
        params_unit: ``(N, D)`` float64 θ normalised to ``[-1, 1]``.
        scene_ranges: The settings varied across the dataset (``--scene-range``), or ``{}``.
        scenes: The ranged settings of each clip's simulation (``{}`` each without ranges).

    Raises:
        UserInputError: when ``root`` is not a complete dataset or ``split`` is unknown.
    """

    def __init__(self, root: str | Path, split: str | None = "train") -> None:
        self.root = Path(root)
        if split is not None and split not in SPLITS:
            raise UserInputError(f"unknown split {split!r}; choose one of {', '.join(SPLITS)}")
        info = read_json(self.root / DATASET_FILE)
        if not isinstance(info, dict) or "config" not in info:
            raise UserInputError(f"{self.root} is not a dataset written by `physinfer dataset generate`")
        if info.get("status") != "complete" or not (self.root / MANIFEST_FILE).is_file():
            raise UserInputError(
                f"{self.root} is incomplete; finish it by re-running `physinfer dataset generate` with the same options"
            )
        self.split = split
        self.info: dict[str, Any] = info
        config = info["config"]
        self.clip_format = ClipFormat.from_dict(config["preset"]["clip"])
        self.parameter_space = ParameterSpace.from_dict(config["parameters"])
        self.param_names: list[str] = self.parameter_space.names
        all_rows = read_manifest(self.root)
        _check_counts(self.root, all_rows, info.get("renders"))
        _check_rows(self.root, all_rows, self.parameter_space)
        self.rows: list[dict[str, Any]] = [row for row in all_rows if split is None or row["split"] == split]
        self.sim_ids = np.array([row["sim"] for row in self.rows], dtype=np.int64)
        self.render_ids = np.array([row["render"] for row in self.rows], dtype=np.int64)
        self.params = np.array(
            [[row["params"][name] for name in self.param_names] for row in self.rows], dtype=np.float64
        ).reshape(len(self.rows), len(self.param_names))
        self.params_unit = np.array([self.parameter_space.to_unit(row["params"]) for row in self.rows]).reshape(
            self.params.shape
        )
        self.scene_ranges: dict[str, list[float]] = dict(config.get("scene_ranges") or {})
        self.scenes: list[dict[str, float]] = [dict(row.get("scene") or {}) for row in self.rows]
        self._shards: dict[str, np.ndarray] = {}

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, i: int) -> np.ndarray:  # type: ignore[override]
        """Clip ``i``: a read-only memory-mapped ``(T, H, W)`` or ``(T, H, W, 3)`` uint8 array."""
        row = self.rows[i]
        return self._shard(row["file"])[row["index"]]

    @property
    def fps(self) -> float:
        """Frame rate of the stored clips."""
        return self.clip_format.fps

    @property
    def render_params(self) -> list[dict[str, Any]]:
        """ζ of each clip."""
        return [row["render_params"] for row in self.rows]

    def clips(self, indices: Sequence[int] | np.ndarray) -> np.ndarray:
        """Several clips copied into one array ``(B, T, H, W)`` or ``(B, T, H, W, 3)`` uint8."""
        indices = np.asarray(indices, dtype=np.int64)
        out = np.empty((len(indices), *self.clip_format.shape), dtype=np.uint8)
        for k, i in enumerate(indices):
            out[k] = self[int(i)]
        return out

    def simulations(self) -> np.ndarray:
        """``(S,)`` the distinct simulation ids of this split, ascending."""
        return np.unique(self.sim_ids)

    def indices_of(self, sim: int) -> np.ndarray:
        """Indices (into this dataset) of the clips rendered from simulation ``sim``."""
        return np.flatnonzero(self.sim_ids == sim)

    def trajectory(self, sim: int) -> Trajectory:
        """The saved trajectory of simulation ``sim``."""
        rows = [row for row in self.rows if row["sim"] == sim]
        if not rows:
            raise UserInputError(f"simulation {sim} is not in split {self.split!r} of {self.root}")
        return Trajectory.load(self.root / rows[0]["trajectory"])

    def _shard(self, file: str) -> np.ndarray:
        shard = self._shards.get(file)
        if shard is None:
            try:
                shard = np.load(self.root / file, mmap_mode="r", allow_pickle=False)
            except (OSError, ValueError) as exc:
                raise UserInputError(
                    f"cannot read {self.root / file} ({exc}); re-run `physinfer dataset generate` on "
                    f"{self.root} to regenerate damaged shards"
                ) from None
            self._shards[file] = shard
        return shard

    def __getstate__(self) -> dict[str, Any]:
        # Memory maps are reopened in each DataLoader worker rather than pickled.
        state = self.__dict__.copy()
        state["_shards"] = {}
        return state


def _check_rows(root: Path, rows: list[dict[str, Any]], space: ParameterSpace) -> None:
    """Refuse a manifest row whose θ is not a finite number inside the parameter bounds, or
    whose ``file`` / ``trajectory`` lies outside the dataset directory (``../../etc/passwd``,
    an absolute path): a manifest is data, and a training set is only as good as its rows."""
    where = root / MANIFEST_FILE
    resolved_root = root.resolve()
    for number, row in enumerate(rows, start=1):
        params = row.get("params")
        if not isinstance(params, dict):
            raise UserInputError(f"{where}: row {number} has no θ (params); the manifest is damaged")
        for spec in space:
            value = params.get(spec.name)
            low, high = spec.bounds
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)
            slack = 1e-9 * max(abs(low), abs(high), 1.0)
            if not ok or not (low - slack <= float(value) <= high + slack):
                raise UserInputError(
                    f"{where}: row {number} (render {row.get('render')}) gives {spec.name}={value!r}, outside its "
                    f"bounds [{low:g}, {high:g}]; the manifest is damaged or not this dataset's — regenerate it "
                    f"with `physinfer dataset generate --out {root}`"
                )
        for key in ("file", "trajectory"):
            name = row.get(key)
            if key == "trajectory" and name is None:
                continue
            inside = isinstance(name, str) and bool(name) and not Path(name).is_absolute()
            if inside:
                target = (root / name).resolve()
                inside = target == resolved_root or resolved_root in target.parents
            if not inside:
                raise UserInputError(
                    f"{where}: row {number} names {key} {name!r}, outside {root}; a dataset reads only its own "
                    "files — regenerate the manifest with `physinfer dataset generate`"
                )
        index = row.get("index")
        if not isinstance(index, int) or isinstance(index, bool) or index < 0:
            raise UserInputError(f"{where}: row {number} has index {index!r}, not a clip's place in its shard")


def _check_counts(root: Path, rows: list[dict[str, Any]], expected: dict[str, int] | None) -> None:
    """Refuse a manifest whose rows per split differ from what ``dataset.json`` recorded (a
    manifest cut at a line boundary reads as valid JSON lines)."""
    if not isinstance(expected, dict):
        return  # written before the counts were recorded
    found = {name: sum(row.get("split") == name for row in rows) for name in expected}
    if found != {name: int(n) for name, n in expected.items()}:
        listed = ", ".join(f"{name} {found[name]} of {expected[name]}" for name in expected)
        raise UserInputError(
            f"{root / MANIFEST_FILE} lists other renders than dataset.json records ({listed}): the manifest is "
            f"damaged or cut; run `physinfer dataset generate --out {root}` again with the same settings"
        )
