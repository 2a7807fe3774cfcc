"""Dataset sizes and clip formats: :class:`SplitCounts`, :class:`ClipFormat`, :class:`DatasetPreset`.

A preset fixes how many simulations and renders each split holds, the stored clip
format and how many simulations one work unit batches. ``paper`` reproduces FlagSim
(Runia et al.): 1,000/150/85 simulations and 14,000/3,800/3,500 renders of 60 frames
at 25 fps, 300×300. ``cpu`` is the small set the shipped default embedder is trained
on. Command-line overrides (``--sims``, ``--renders-per-sim``, ``--seeds-per-theta``)
derive a new preset with :meth:`DatasetPreset.with_overrides`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, replace
from typing import Any

from physinfer.errors import UserInputError

SPLITS: tuple[str, ...] = ("train", "val", "test")
#: The most simulations one dataset may plan (FlagSim, the paper's, has 1,235): the plan
#: holds a few records per simulation, so a mistyped count would take the machine's memory.
MAX_SIMULATIONS = 1_000_000
#: The most renders (stored clips) one dataset may plan (FlagSim has 21,300).
MAX_RENDERS = 10_000_000
#: The longest side of a stored clip, in pixels.
MAX_CLIP_SIDE = 4096
#: The most frames of a stored clip.
MAX_CLIP_FRAMES = 10_000


@dataclass(frozen=True)
class SplitCounts:
    """One non-negative count per split.

    Attributes:
        train: Count for the training split.
        val: Count for the validation split.
        test: Count for the test split.
    """

    train: int
    val: int
    test: int

    def validate(self) -> None:
        """Raise :class:`ValueError` for a negative or non-integer count."""
        for split in SPLITS:
            value = self[split]
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise ValueError(f"{split} count must be a non-negative integer, got {value!r}")

    def __post_init__(self) -> None:
        self.validate()

    def __getitem__(self, split: str) -> int:
        if split not in SPLITS:
            raise KeyError(split)
        return int(getattr(self, split))

    @property
    def total(self) -> int:
        """Sum over the splits."""
        return self.train + self.val + self.test

    def to_dict(self) -> dict[str, int]:
        """``{"train": ..., "val": ..., "test": ...}``."""
        return {split: self[split] for split in SPLITS}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SplitCounts:
        """Inverse of :meth:`to_dict`."""
        return cls(**{split: int(d[split]) for split in SPLITS})


@dataclass(frozen=True)
class ClipFormat:
    """How clips are stored: length, frame rate, size and colour.

    Stored clips are uint8 arrays of shape ``(T, H, W)`` when ``channels == 1``
    (grayscale, BT.601 luma) or ``(T, H, W, 3)`` when ``channels == 3`` (RGB).

    Attributes:
        n_frames: ``T``, frames per clip.
        fps: Frame rate in Hz; rendered clips are resampled to it.
        height: ``H`` in pixels.
        width: ``W`` in pixels.
        channels: 1 (grayscale) or 3 (RGB).
    """

    n_frames: int = 60
    fps: float = 25.0
    height: int = 224
    width: int = 224
    channels: int = 1

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`ValueError` for a non-positive size or an unsupported channel count."""
        if self.n_frames < 1 or self.height < 1 or self.width < 1:
            raise ValueError(f"clip format needs positive frames and size, got {self}")
        if not self.fps > 0:
            raise ValueError(f"clip fps must be positive, got {self.fps}")
        if self.channels not in (1, 3):
            raise ValueError(f"channels must be 1 (grayscale) or 3 (RGB), got {self.channels}")

    @property
    def shape(self) -> tuple[int, ...]:
        """Shape of one stored clip: ``(T, H, W)`` or ``(T, H, W, 3)``."""
        base = (self.n_frames, self.height, self.width)
        return base if self.channels == 1 else (*base, 3)

    @property
    def nbytes(self) -> int:
        """Bytes of one stored clip."""
        return self.n_frames * self.height * self.width * self.channels

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ClipFormat:
        """Inverse of :meth:`to_dict`."""
        return cls(
            n_frames=int(d["n_frames"]),
            fps=float(d["fps"]),
            height=int(d["height"]),
            width=int(d["width"]),
            channels=int(d["channels"]),
        )


@dataclass(frozen=True)
class DatasetPreset:
    """The size and format of a dataset.

    Renders are spread over a split's simulations as evenly as possible: with ``S``
    simulations and ``R`` renders, simulation ``i`` of the split gets ``R // S`` renders,
    plus one when ``i < R % S``.

    Attributes:
        name: Identifier used by ``--preset``.
        sims: Simulations per split.
        renders: Renders (clips) per split; at least one per simulation.
        clip: Stored clip format.
        sims_per_unit: Simulations batched into one work unit (one shard file). Part of
            the dataset's identity: batched simulators need not give bit-identical
            results for different batch compositions.
        seeds_per_theta: Consecutive simulations of a split that share one θ and differ
            only in the simulator's seed (1: every simulation draws its own θ). More than
            one gives positives across simulation seeds (``--positives parameters`` when
            training an embedder). Part of the dataset's identity.
        description: One line for humans.
    """

    name: str
    sims: SplitCounts
    renders: SplitCounts
    clip: ClipFormat = ClipFormat()
    sims_per_unit: int = 4
    seeds_per_theta: int = 1
    description: str = ""

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`ValueError` for inconsistent counts."""
        self.sims.validate()
        self.renders.validate()
        self.clip.validate()
        if self.sims.total < 1:
            raise ValueError(f"preset {self.name!r} has no simulations")
        if self.sims_per_unit < 1:
            raise ValueError(f"sims_per_unit must be at least 1, got {self.sims_per_unit}")
        if isinstance(self.seeds_per_theta, bool) or not isinstance(self.seeds_per_theta, int):
            raise ValueError(f"seeds_per_theta must be an integer, got {self.seeds_per_theta!r}")
        if self.seeds_per_theta < 1:
            raise ValueError(f"seeds_per_theta must be at least 1, got {self.seeds_per_theta}")
        for split in SPLITS:
            s, r = self.sims[split], self.renders[split]
            if r < s or (s == 0 and r > 0):
                raise ValueError(
                    f"preset {self.name!r}: split {split!r} has {r} renders for {s} simulations; "
                    "every simulation needs at least one render"
                )

    def renders_of(self, split: str, local: int) -> int:
        """Renders of simulation ``local`` (0-based) of ``split``."""
        s, r = self.sims[split], self.renders[split]
        return r // s + (1 if local < r % s else 0)

    def with_overrides(
        self,
        *,
        sims: int | SplitCounts | None = None,
        renders_per_sim: int | SplitCounts | None = None,
        sims_per_unit: int | None = None,
        n_frames: int | None = None,
        size: tuple[int, int] | None = None,
        channels: int | None = None,
        seeds_per_theta: int | None = None,
    ) -> DatasetPreset:
        """A copy with other counts or clip format (the command-line overrides).

        Args:
            sims: Total simulations, split in this preset's proportions, or explicit
                counts per split.
            renders_per_sim: Renders of every simulation, for all splits or per split.
                When not given, each split keeps this preset's average renders per
                simulation (rounded, at least one).
            sims_per_unit: Simulations per work unit.
            n_frames: Frames per stored clip.
            size: ``(H, W)`` of stored clips.
            channels: 1 (grayscale) or 3 (RGB) stored clips.
            seeds_per_theta: Consecutive simulations sharing one θ (see the class).

        Raises:
            UserInputError: for a count that leaves no simulation at all, an invalid
                clip format, or ``seeds_per_theta`` below 1.
        """
        new_sims = self._checked_sims(sims)
        _check_clip_overrides(n_frames, size, seeds_per_theta)
        renders = self._renders_for(new_sims, renders_per_sim)
        clip_changes = _clip_changes(n_frames, size, channels)
        changed = (
            sims is not None
            or renders_per_sim is not None
            or sims_per_unit is not None
            or (seeds_per_theta is not None and seeds_per_theta != self.seeds_per_theta)
            or bool(clip_changes)
        )
        try:
            return replace(
                self,
                name=f"{self.name}+custom" if changed and not self.name.endswith("+custom") else self.name,
                description=f"{self.name} with overrides" if changed else self.description,
                sims=new_sims,
                renders=renders,
                sims_per_unit=self.sims_per_unit if sims_per_unit is None else sims_per_unit,
                seeds_per_theta=self.seeds_per_theta if seeds_per_theta is None else seeds_per_theta,
                clip=replace(self.clip, **clip_changes),
            )
        except ValueError as exc:
            raise UserInputError(str(exc)) from None

    def _checked_sims(self, sims: int | SplitCounts | None) -> SplitCounts:
        """``--sims`` as per-split counts (this preset's when not given), refused when it makes
        no simulation or more than a dataset holds."""
        new_sims = self.sims if sims is None else _as_split_counts(sims, self.sims)
        if new_sims.total < 1:
            raise UserInputError("--sims must give at least one simulation")
        if new_sims.total > MAX_SIMULATIONS:
            raise UserInputError(
                f"--sims: {new_sims.total} simulations; a dataset holds at most {MAX_SIMULATIONS:,} "
                "(the paper's FlagSim has 1,235): make several datasets"
            )
        return new_sims

    def _renders_for(
        self, new_sims: SplitCounts, renders_per_sim: int | SplitCounts | None
    ) -> SplitCounts:
        """Renders per split for ``new_sims``: ``renders_per_sim`` each, or this preset's
        average per simulation; refused when more than a dataset holds."""
        if renders_per_sim is None:
            renders = SplitCounts(
                **{
                    split: _scaled_renders(new_sims[split], self.sims[split], self.renders[split])
                    for split in SPLITS
                }
            )
        else:
            per_sim = (
                renders_per_sim
                if isinstance(renders_per_sim, SplitCounts)
                else SplitCounts(renders_per_sim, renders_per_sim, renders_per_sim)
            )
            if any(per_sim[split] < 1 for split in SPLITS if new_sims[split] > 0):
                raise UserInputError("--renders-per-sim must be at least 1")
            renders = SplitCounts(**{split: new_sims[split] * per_sim[split] for split in SPLITS})
        if renders.total > MAX_RENDERS:
            option = "--renders-per-sim" if renders_per_sim is not None else "--sims"
            raise UserInputError(
                f"{option}: {renders.total} renders; a dataset holds at most {MAX_RENDERS:,} "
                "(the paper's FlagSim has 21,300): make several datasets"
            )
        return renders

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description.

        ``seeds_per_theta`` appears only when it is not 1, so the stored identity of
        datasets made before the option existed (and of new ones that do not use it)
        is unchanged and they still resume.
        """
        described: dict[str, Any] = {
            "name": self.name,
            "sims": self.sims.to_dict(),
            "renders": self.renders.to_dict(),
            "clip": self.clip.to_dict(),
            "sims_per_unit": self.sims_per_unit,
            "description": self.description,
        }
        if self.seeds_per_theta != 1:
            described["seeds_per_theta"] = self.seeds_per_theta
        return described

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> DatasetPreset:
        """Inverse of :meth:`to_dict`."""
        return cls(
            name=str(d["name"]),
            sims=SplitCounts.from_dict(d["sims"]),
            renders=SplitCounts.from_dict(d["renders"]),
            clip=ClipFormat.from_dict(d["clip"]),
            sims_per_unit=int(d["sims_per_unit"]),
            seeds_per_theta=int(d.get("seeds_per_theta", 1)),
            description=str(d.get("description", "")),
        )


def _as_split_counts(sims: int | SplitCounts, proportions: SplitCounts) -> SplitCounts:
    """``sims`` as per-split counts; a total is split like ``proportions`` (largest remainder)."""
    if isinstance(sims, SplitCounts):
        return sims
    if sims < 1:
        raise UserInputError(f"--sims must be at least 1, got {sims}")
    weights = [proportions[split] / proportions.total for split in SPLITS]
    raw = [sims * w for w in weights]
    counts = [int(x) for x in raw]
    by_remainder = sorted(range(len(SPLITS)), key=lambda i: (-(raw[i] - counts[i]), i))
    for i in by_remainder[: sims - sum(counts)]:
        counts[i] += 1
    # A split the preset uses should not vanish when there are enough simulations for all.
    for i in range(len(SPLITS)):
        if counts[i] == 0 and weights[i] > 0 and sims >= len(SPLITS):
            donor = max(range(len(SPLITS)), key=lambda j: counts[j])
            counts[donor] -= 1
            counts[i] = 1
    return SplitCounts(*counts)


def _check_clip_overrides(
    n_frames: int | None, size: tuple[int, int] | None, seeds_per_theta: int | None
) -> None:
    """Refuse a clip length or size out of bounds, or ``seeds_per_theta`` below 1."""
    if n_frames is not None and not 1 <= n_frames <= MAX_CLIP_FRAMES:
        raise UserInputError(f"--frames {n_frames}: give 1 to at most {MAX_CLIP_FRAMES:,} frames per clip")
    if size is not None and not all(1 <= side <= MAX_CLIP_SIDE for side in size):
        shown = "x".join(map(str, size))
        raise UserInputError(f"--size {shown}: give 1 to at most {MAX_CLIP_SIDE} pixels a side")
    if seeds_per_theta is not None and (
        isinstance(seeds_per_theta, bool) or not isinstance(seeds_per_theta, int) or seeds_per_theta < 1
    ):
        raise UserInputError(
            f"--seeds-per-theta must be a whole number of at least 1 (1: every simulation draws "
            f"its own θ), got {seeds_per_theta!r}"
        )


def _clip_changes(
    n_frames: int | None, size: tuple[int, int] | None, channels: int | None
) -> dict[str, int]:
    """The :class:`ClipFormat` fields the overrides change."""
    clip_changes: dict[str, int] = {}
    if n_frames is not None:
        clip_changes["n_frames"] = n_frames
    if size is not None:
        clip_changes["height"], clip_changes["width"] = size
    if channels is not None:
        clip_changes["channels"] = channels
    return clip_changes


def _scaled_renders(new_sims: int, old_sims: int, old_renders: int) -> int:
    """Renders for ``new_sims`` simulations at the old average renders per simulation."""
    if new_sims == 0:
        return 0
    per_sim = old_renders / old_sims if old_sims else 1.0
    return max(new_sims, int(round(new_sims * per_sim)))


def parse_split_counts(text: str, what: str) -> int | SplitCounts:
    """Parse ``"N"`` or ``"TRAIN,VAL,TEST"`` from the command line.

    Raises:
        UserInputError: for anything else.
    """
    parts = [p.strip() for p in text.split(",")]
    try:
        values = [int(p) for p in parts]
    except ValueError:
        raise UserInputError(f"{what} expects N or TRAIN,VAL,TEST (integers), got {text!r}") from None
    if any(v < 0 for v in values):
        raise UserInputError(f"{what}: counts must not be negative, got {text!r}")
    largest = MAX_RENDERS if "render" in what else MAX_SIMULATIONS
    if any(v > largest for v in values):
        raise UserInputError(f"{what} {text}: at most {largest:,} per dataset; make several datasets")
    if len(values) == 1:
        return values[0]
    if len(values) == 3:
        return SplitCounts(*values)
    raise UserInputError(f"{what} expects N or TRAIN,VAL,TEST, got {len(values)} numbers in {text!r}")


PAPER_PRESET = DatasetPreset(
    name="paper",
    sims=SplitCounts(1000, 150, 85),
    renders=SplitCounts(14000, 3800, 3500),
    clip=ClipFormat(n_frames=60, fps=25.0, height=300, width=300, channels=1),
    sims_per_unit=4,
    description="FlagSim as in the paper: 1,000/150/85 simulations, 14,000/3,800/3,500 renders, "
    "60 frames at 25 fps, 300×300 (≈345 GB RGB, ≈115 GB --gray)",
)

CPU_PRESET = DatasetPreset(
    name="cpu",
    sims=SplitCounts(160, 24, 24),
    renders=SplitCounts(1280, 192, 192),
    clip=ClipFormat(n_frames=60, fps=25.0, height=224, width=224, channels=1),
    sims_per_unit=4,
    description="laptop-sized: 160/24/24 simulations, 8 renders each (1,280/192/192 renders), "
    "60 frames at 25 fps, 224×224 (≈15 GB RGB, ≈5 GB --gray)",
)

DEFAULT_PRESETS: dict[str, DatasetPreset] = {p.name: p for p in (PAPER_PRESET, CPU_PRESET)}
