"""Result objects of the API that have no home in the layers below it.

:class:`~physinfer.refinement.RefineResult` (``refine``) and
:class:`~physinfer.posterior.workflow.PosteriorReport` (``infer``) are the loop's own
results; a simulation and a diagnosis get theirs here. Each has ``to_dict()`` (the JSON
the CLI prints) and ``plot()`` (a matplotlib figure).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.discrepancy.figures import gaps_figure
from physinfer.discrepancy.records import Candidate, Screened, Verdict
from physinfer.types import Clip, Trajectory


@dataclass
class Simulation:
    """One simulation of a phenomenon and, when rendered, its clip.

    Attributes:
        plugin: The phenomenon.
        params: Every parameter's value (the defaults filled in).
        effects: Effects switched in.
        seed: Seed of the simulation.
        trajectory: The simulated trajectory.
        clip: Its rendering (``None`` when not rendered).
        render_params: ζ it was rendered with.
        seconds: Time to simulate and to render.
        paths: Files written (``video``, ``trajectory``).
        scene: The scene's settings when given (``scene_set``), else ``None``.
    """

    plugin: str
    params: dict[str, float]
    effects: tuple[str, ...]
    seed: int
    trajectory: Trajectory
    clip: Clip | None = None
    render_params: dict[str, Any] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    paths: dict[str, str] = field(default_factory=dict)
    scene: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``physinfer simulate --json`` prints."""
        out: dict[str, Any] = {
            "plugin": self.plugin,
            "params": self.params,
            "effects": list(self.effects),
        }
        out["seed"] = self.seed
        if self.scene is not None:
            out["scene"] = self.scene
        out["simulate_s"] = self.seconds.get("simulate")
        out.update(n_frames=self.trajectory.n_frames, fps=self.trajectory.fps)
        if "trajectory" in self.paths:
            out["trajectory"] = self.paths["trajectory"]
        if "video" in self.paths:
            out.update(
                render_s=self.seconds.get("render"),
                video=self.paths["video"],
                render_params=self.render_params,
            )
        return out

    def plot(self, n: int = 6) -> Any:
        """``n`` frames of the clip side by side (a matplotlib figure).

        Raises:
            ValueError: the simulation was not rendered.
        """
        if self.clip is None:
            raise ValueError("this simulation was not rendered (simulate(..., render=True))")
        return frames_figure(self.clip, n)


@dataclass
class Diagnosis:
    """What ``diagnose`` found: whether the model is misspecified and which effect it lacks.

    Attributes:
        misspecified: Whether the model disagrees with the video beyond its noise.
        named_effect: The effect that closes the gap, or ``None``.
        gap_before: The baseline fit's gap to the target.
        gap_after: The gap with the named effect (the baseline's when none is named).
        candidates: One :class:`~physinfer.discrepancy.records.Candidate` per effect refined
            (gap, ratio, p-value, significance, ...); each also reads as its dict
            (``d.candidates[0]["gap"]``).
        out: The diagnosis directory.
        report: Everything ``diagnosis.json`` holds.
        screened: The effects left out before refinement, each a
            :class:`~physinfer.discrepancy.records.Screened` with its ``reason`` (no fit could
            name them on this target; see :mod:`physinfer.discrepancy.screen`).
        verdict: The decision as a :class:`~physinfer.discrepancy.records.Verdict`: by which
            test, the threshold, and the notes (``named_leaves``, ``unnamed``, ``lead``: each a
            :class:`~physinfer.discrepancy.records.Note` with ``effect``, ``message`` and ``settle``);
            :meth:`from_report` always sets it; given ``None``, it is read from ``report``.
    """

    misspecified: bool
    named_effect: str | None
    gap_before: float
    gap_after: float
    candidates: list[Candidate]
    out: Path
    report: dict[str, Any]
    screened: list[Screened] = field(default_factory=list)
    verdict: Verdict | None = None

    def __post_init__(self) -> None:
        if self.verdict is None and "tested_gap" in self.report:  # a report diagnose wrote
            self.verdict = Verdict.from_report(self.report)

    @classmethod
    def from_report(cls, report: dict[str, Any], out: Path) -> Diagnosis:
        """Wrap the report ``run_diagnosis`` returns."""
        return cls(
            misspecified=bool(report["misspecified"]),
            named_effect=report.get("named_effect"),
            gap_before=float(report["gap_before"]),
            gap_after=float(report["gap_after"]),
            candidates=[Candidate.from_dict(c) for c in report.get("candidates", [])],
            out=Path(out),
            report=report,
            screened=[Screened.from_dict(s) for s in report.get("screened") or []],
            verdict=Verdict.from_report(report),
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``physinfer diagnose --json`` prints (``diagnosis.json``)."""
        return self.report

    def plot(self) -> Any:
        """Each model's distances to the target and its gap against the noise floor, the null
        scale and the threshold (a matplotlib figure; ``gaps.png`` is the same drawing)."""
        best = self.report["best_baseline"]
        models = [{"label": "baseline (best)", "gap": best["gap"], "distances": best["to_target"]}]
        models += [{"label": c.effect, "gap": c.gap, "distances": list(c.distances)} for c in self.candidates]
        return gaps_figure(
            models,
            floor=self.report["noise_floor"],
            scale=self.report["null_scale"],
            threshold=self.report["threshold"],
            named=self.named_effect,
        )


def frames_figure(clip: Clip, n: int = 6) -> Any:
    """``n`` evenly spaced frames of ``clip`` side by side, each titled with its time (a
    matplotlib figure, no pyplot state)."""
    from matplotlib.figure import Figure

    frames = clip.frames
    picks = np.linspace(0, len(frames) - 1, num=min(n, len(frames))).round().astype(int)
    fig = Figure(figsize=(2.2 * len(picks), 2.4), layout="constrained")
    for ax, i in zip(fig.subplots(1, len(picks), squeeze=False)[0], picks, strict=True):
        ax.imshow(frames[i])
        ax.set_title(f"t = {i / clip.fps:.2f} s", fontsize=8)
        ax.axis("off")
    return fig
