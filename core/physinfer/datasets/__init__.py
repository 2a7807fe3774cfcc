"""Dataset generation for any phenomenon, locally or on a Dask cluster, and loading for training.

A phenomenon supplies a :class:`DatasetGenerator` (θ and ζ sampling, simulation,
rendering; :class:`PhenomenonDatasetGenerator` builds one from any
:class:`~physinfer.roles.Phenomenon`); :func:`generate_dataset` plans the dataset from a
seed, runs work units on an executor, writes shards of uint8 clips, trajectories and a
manifest, and resumes interrupted runs; :class:`ClipDataset` reads a split back,
memory-mapped. The format is described in ``docs/datasets.md``.
"""

from physinfer.datasets.engine import GenerateResult, generate_dataset
from physinfer.datasets.executors import (
    ExecutorInfo,
    InlineExecutor,
    default_workers,
    open_executor,
)
from physinfer.datasets.generator import DatasetGenerator, PhenomenonDatasetGenerator, generator_for
from physinfer.datasets.loader import ClipDataset
from physinfer.datasets.plan import SimulationPlan, UnitPlan, plan_dataset
from physinfer.datasets.presets import (
    CPU_PRESET,
    DEFAULT_PRESETS,
    PAPER_PRESET,
    SPLITS,
    ClipFormat,
    DatasetPreset,
    SplitCounts,
    parse_split_counts,
)
from physinfer.datasets.resume import GenerateProgress

__all__ = [
    "CPU_PRESET",
    "DEFAULT_PRESETS",
    "PAPER_PRESET",
    "SPLITS",
    "ClipDataset",
    "ClipFormat",
    "DatasetGenerator",
    "DatasetPreset",
    "ExecutorInfo",
    "GenerateProgress",
    "GenerateResult",
    "InlineExecutor",
    "PhenomenonDatasetGenerator",
    "SimulationPlan",
    "SplitCounts",
    "UnitPlan",
    "default_workers",
    "generate_dataset",
    "generator_for",
    "open_executor",
    "parse_split_counts",
    "plan_dataset",
]
