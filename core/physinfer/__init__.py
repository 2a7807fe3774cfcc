"""physinfer: measure physical parameters from video by refining simulations.

The commands as functions (:mod:`physinfer.api`, re-exported here)::

    import physinfer

    result = physinfer.refine("pendulum_lab", steps=20, out="runs/pendulum")
    result.best_params, result.posterior, result.to_dict(), result.plot()

and what a plugin is written against: the roles (:class:`Simulator`, :class:`Renderer`,
:class:`Embedder`, :class:`Optimizer`, :class:`Effect`), the :class:`Phenomenon` record,
parameter specs, the :class:`Trajectory` and :class:`Clip` value types, and the plugin
machinery. Importing this package is cheap (no torch, pyrender or Ax): the API's names
are imported on first use.
"""

from physinfer.errors import PhysinferError, SimulationFailed, UserInputError
from physinfer.hooks import hookimpl
from physinfer.parameters import ParameterSpace, ParameterSpec
from physinfer.plugins import get_plugin_manager, load_registry
from physinfer.roles import (
    Effect,
    Embedder,
    Optimizer,
    Phenomenon,
    Renderer,
    Simulator,
    Target,
    Trial,
)
from physinfer.types import Clip, Trajectory

__version__ = "0.1.0"

#: The commands and their options, from :mod:`physinfer.api` (imported on first use).
API_NAMES = (
    "simulate",
    "refine",
    "diagnose",
    "infer",
    "train_posterior",
    "evaluate_calibration",
    "prepare",
    "render",
    "SimulateOptions",
    "RefineOptions",
    "DiagnoseOptions",
    "InferOptions",
    "PosteriorTrainOptions",
    "CalibrationOptions",
    "PrepareOptions",
    "RenderOptions",
)


def __getattr__(name: str) -> object:
    if name in API_NAMES:
        from physinfer import api

        return getattr(api, name)
    raise AttributeError(f"module 'physinfer' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *API_NAMES])

# The API's names are left out of ``__all__``: a star import stays as cheap as the package.
__all__ = [
    "Clip",
    "Effect",
    "Embedder",
    "Optimizer",
    "ParameterSpace",
    "ParameterSpec",
    "Phenomenon",
    "PhysinferError",
    "Renderer",
    "SimulationFailed",
    "Simulator",
    "Target",
    "Trajectory",
    "Trial",
    "UserInputError",
    "get_plugin_manager",
    "hookimpl",
    "load_registry",
]
