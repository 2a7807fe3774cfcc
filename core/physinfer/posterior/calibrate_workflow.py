"""Simulation-based calibration of an estimator (``physinfer evaluate calibration``): ranks,
expected coverage, posterior-median errors and contraction on a dataset's held-out clips.

The clips are checked as users give videos (:mod:`physinfer.as_given`: camera effects,
H.264 and ``infer``'s conditioning) — the headline numbers — and, beside them, as stored
(``in_memory``): an estimator calibrated on its training format can be wrong on every video.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.as_given import CameraModel
from physinfer.datasets.loader import ClipDataset
from physinfer.errors import UserInputError
from physinfer.io import atomic_write_json, check_output_dir
from physinfer.posterior.calibration import calibrate, calibration_figure, plot_calibration
from physinfer.posterior.features import TargetPath, embed_dataset
from physinfer.posterior.inputs import checked_rows
from physinfer.posterior.loading import (
    ProgressFn,
    check_dataset,
    estimator_embedder,
    load_estimator,
    no_progress,
)
from physinfer.posterior.summary import PRIOR_VARIANCE
from physinfer.registry import Registry


@dataclass
class CalibrationReport:
    """Simulation-based calibration of an estimator on a dataset split."""

    calibration: Any
    estimator: Path
    data: Path
    split: str
    median_abs_error: dict[str, float]
    contraction: dict[str, float]
    paths: dict[str, str] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    targets: str = "as stored"
    in_memory: CalibrationReport | None = None

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``physinfer evaluate calibration --json`` prints: the calibration on the
        clips as users give them, and ``in_memory``: the same on the clips as stored."""
        d = self.calibration.to_dict()
        for name, row in d["parameters"].items():
            row["median_abs_error"] = self.median_abs_error[name]
            row["mean_contraction"] = self.contraction[name]
        d.update(estimator=str(self.estimator), data=str(self.data), split=self.split, targets=self.targets)
        if self.in_memory is not None:
            d["in_memory"] = {
                k: v for k, v in self.in_memory.to_dict().items() if k not in ("files", "seconds", "estimator")
            }
        d.update(files=self.paths, seconds=self.seconds)
        return d

    def plot(self) -> Any:
        """Rank histograms and coverage per parameter (a matplotlib figure;
        ``calibration.png`` is the same drawing)."""
        return calibration_figure(self.calibration, title=self.title)

    @property
    def title(self) -> str:
        """What was checked: the dataset and its split."""
        return f"{self.data.name} ({self.split})"


def evaluate_calibration(
    registry: Registry,
    *,
    plugin: str,
    data: Path,
    out: Path,
    posterior: Path | None = None,
    split: str = "test",
    n_samples: int = 1000,
    seed: int = 0,
    device: str | None = None,
    progress: ProgressFn = no_progress,
) -> CalibrationReport:
    """Ranks, expected coverage, posterior-median errors and contraction on held-out clips.

    The held-out clips are embedded with the estimator's own embedder (cached beside the
    dataset like the training clips), once as users give videos (the report) and once as
    stored (``in_memory``).
    """
    if n_samples < 50:
        raise UserInputError(
            f"--samples {n_samples}: at least 50 posterior samples per simulation are needed"
        )
    out = Path(out)
    check_output_dir(out)
    t_start = time.perf_counter()
    estimator, estimator_path = load_estimator(registry, plugin, posterior, device)
    dataset = ClipDataset(data, split)
    check_dataset(dataset, plugin)
    if dataset.parameter_space.to_dict() != estimator.parameter_space.to_dict():
        raise UserInputError(
            f"{data} was drawn from another parameter space than the estimator's; calibrate on a dataset "
            "of the same model"
        )
    if dict(dataset.scene_ranges) != dict(estimator.config.scene_ranges or {}):
        raise UserInputError(
            f"{data} varies the scene over {dataset.scene_ranges or 'nothing'}, the estimator over "
            f"{estimator.config.scene_ranges or 'nothing'}; calibrate on a dataset made like its training set"
        )
    pipeline = estimator_embedder(registry, estimator, device)
    c = estimator.config
    embedder_info = {
        "embedder": c.embedder,
        "embedder_frames": c.embedder_frames,
        "embedder_fps": c.embedder_fps,
        "probe": c.probe,
    }
    given = _target_path(estimator, pipeline.phenomenon)
    reports = []
    for path, label in ((given, "as given"), (None, "as stored")):
        t0 = time.perf_counter()
        pairs = embed_dataset(
            data, split, pipeline.embedder, embedder_info, as_given=path,
            on_progress=lambda done, total, label=label: progress(f"embedding {label}", done, total),
        ).with_render_inputs(c.render_inputs)  # fmt: skip
        t1 = time.perf_counter()
        report = _calibrate_pairs(
            estimator, pairs, n_samples, seed, progress,
            {"estimator": estimator_path, "data": Path(data), "split": split, "targets": label},
        )  # fmt: skip
        report.seconds = {"load": t0 - t_start, "embed": t1 - t0, "calibrate": time.perf_counter() - t1}
        reports.append(report)
    report, report.in_memory = reports
    out.mkdir(parents=True, exist_ok=True)
    report.paths["plot"] = str(
        plot_calibration(report.calibration, out / "calibration.png", title=f"{plugin}: {report.title}")
    )
    report.paths["report"] = str(out / "calibration.json")
    atomic_write_json(out / "calibration.json", report.to_dict())
    pipeline.renderer.close()
    return report


def _target_path(estimator: Any, phenomenon: Any) -> TargetPath:
    """How held-out clips are sent down a user's path: the camera model the estimator was
    trained with (the default one for an estimator trained on stored clips)."""
    trained = (estimator.config.targets or {}).get("as_given")
    if trained:
        return TargetPath(phenomenon, CameraModel.from_dict(trained["camera"]), int(trained["seed"]))
    return TargetPath(phenomenon, CameraModel(), 0)


def _calibrate_pairs(
    estimator: Any, pairs: Any, n_samples: int, seed: int, progress: ProgressFn, where: dict[str, Any]
) -> CalibrationReport:
    """Ranks, coverage, median errors and contraction of ``estimator`` on embedded ``pairs``;
    ``where``: the report's ``estimator`` (path), ``data``, ``split`` and ``targets``."""
    names = estimator.parameter_space.names
    medians = np.empty_like(pairs.theta_unit, dtype=np.float64)
    variances = np.empty_like(medians)
    inputs = checked_rows(estimator.config.inputs, pairs.conditions)

    def sampler(xs: np.ndarray, n: int, batch_seed: int) -> np.ndarray:
        return estimator.sample_unit_batched(xs, n, seed=batch_seed)

    cal = calibrate(
        pairs.theta_unit.astype(np.float64),
        inputs,
        _recording(sampler, medians, variances),
        names,
        n_samples=n_samples,
        seed=seed,
        on_progress=lambda done, total: progress("sampling", done, total),
    )
    space = estimator.parameter_space
    truth = pairs.theta
    med_phys = np.stack([spec.from_unit(medians[:, i]) for i, spec in enumerate(space)], axis=1)
    return CalibrationReport(
        calibration=cal,
        **where,
        median_abs_error={
            n: float(np.median(np.abs(med_phys[:, i] - truth[:, i]))) for i, n in enumerate(names)
        },
        contraction={
            n: float(np.mean(1 - variances[:, i] / PRIOR_VARIANCE)) for i, n in enumerate(names)
        },
    )


def _recording(
    sampler: Callable[[np.ndarray, int, int], np.ndarray],
    medians: np.ndarray,
    variances: np.ndarray,
) -> Callable[[np.ndarray, int, int], np.ndarray]:
    """Wrap ``sampler`` to keep each pair's posterior median and variance as batches pass."""
    state = {"start": 0}

    def wrapped(xs: np.ndarray, n: int, seed: int) -> np.ndarray:
        samples = sampler(xs, n, seed)
        start, stop = state["start"], state["start"] + len(xs)
        medians[start:stop] = np.median(samples, axis=0)
        variances[start:stop] = samples.var(axis=0)
        state["start"] = stop
        return samples

    return wrapped
