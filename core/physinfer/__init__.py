"""physinfer: measure physical parameters from video by refining simulations.

The public API: the roles (:class:`Simulator`, :class:`Renderer`, :class:`Embedder`,
:class:`Optimizer`, :class:`Effect`), the :class:`Phenomenon` record, parameter specs,
the :class:`Trajectory` and :class:`Clip` value types, and the plugin machinery. Importing
this package is cheap: no torch, pyrender or Ax.
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
