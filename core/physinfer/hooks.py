"""pluggy hook specifications of physinfer.

Every hook takes a :class:`~physinfer.registry.Registry` view and adds entries to it
with ``registry.add_*``; entries name their implementation as a ``"module:attr"``
string (or a callable) that is imported only when first used, so listing plugins and
``physinfer --help`` never import torch, pyrender or Ax.

All hooks are called once, when :func:`physinfer.plugins.load_registry` builds the
registry, in plugin registration order, each plugin's implementation separately (so a
failing plugin is reported by name and the others still load).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:
    from physinfer.registry import Registry

PROJECT_NAME = "physinfer"
hookspec = pluggy.HookspecMarker(PROJECT_NAME)
hookimpl = pluggy.HookimplMarker(PROJECT_NAME)


@hookspec
def physinfer_register_phenomena(registry: Registry) -> None:
    """Register phenomena with ``registry.add_phenomenon(name, factory, description)``.

    Called when the registry is built. ``factory`` returns a
    :class:`~physinfer.roles.Phenomenon`.
    """


@hookspec
def physinfer_register_optimizers(registry: Registry) -> None:
    """Register optimizers with ``registry.add_optimizer(name, factory, description)``.

    Called when the registry is built. ``factory(dim=, seed=, names=, **options)``
    returns a :class:`~physinfer.roles.Optimizer`.
    """


@hookspec
def physinfer_register_embedders(registry: Registry) -> None:
    """Register embedders with ``registry.add_embedder(name, factory, description)``.

    Called when the registry is built. ``factory(model=None, device=None)`` returns an
    :class:`~physinfer.roles.Embedder`; ``model`` is a weights file or ``None`` for the
    shipped default.
    """


@hookspec
def physinfer_register_effects(registry: Registry) -> None:
    """Register effects with ``registry.add_effect(name, factory, phenomenon, description)``.

    Called when the registry is built. ``factory()`` returns an
    :class:`~physinfer.roles.Effect` for the named phenomenon.
    """


@hookspec
def physinfer_register_commands(registry: Registry) -> None:
    """Register CLI commands with ``registry.add_command(name, factory, help)``.

    Called when the CLI is built. ``factory`` is a ``typer.Typer`` (added as a command
    group) or a function (added as a command); its module must be cheap to import.
    """
