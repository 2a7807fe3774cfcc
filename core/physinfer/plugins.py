"""Plugin discovery: a pluggy manager fed from the ``physinfer`` entry-point group.

Built-in and third-party plugins are found the same way. A plugin that fails to import,
implements a hook physinfer does not have (a misspelled name) or whose hook raises is
recorded with its name and error and left out; the others still load.
:func:`check_references` imports every ``"module:attr"`` the plugins registered, so
``physinfer plugins`` shows a lazily named implementation that fails to import.
``PHYSINFER_DISABLED_PLUGINS`` (comma-separated entry-point names) blocks plugins.

The host's plugins (those of the ``physinfer`` distribution: ``builtins``, ``flag``,
``hanging_cloth``) register first, then the others in entry-point name order; a name already
taken is refused (:class:`~physinfer.registry.Registry`), so no third-party plugin can replace
a built-in phenomenon, optimizer, embedder, effect or command, whatever its name sorts as or
its hooks' ``tryfirst``.
"""

from __future__ import annotations

import difflib
import os
import traceback
from dataclasses import dataclass, field
from importlib import metadata
from types import ModuleType
from typing import Any

import pluggy

from physinfer import hooks
from physinfer.registry import KINDS, Registry

ENTRY_POINT_GROUP = "physinfer"
#: The distribution whose plugins are the host's own, registered before any other.
HOST_DISTRIBUTION = "physinfer"
DISABLED_ENV = "PHYSINFER_DISABLED_PLUGINS"
REGISTER_HOOKS = (
    "physinfer_register_phenomena",
    "physinfer_register_optimizers",
    "physinfer_register_embedders",
    "physinfer_register_effects",
    "physinfer_register_commands",
)


@dataclass
class PluginInfo:
    """What is known about one plugin.

    Attributes:
        name: Entry-point name (what ``PHYSINFER_DISABLED_PLUGINS`` takes).
        distribution: Distribution that declares it, if any.
        version: That distribution's version.
        module: Imported module name (``value`` of the entry point).
        error: ``"ExcType: message"`` if it failed to load or register, else ``None``.
        traceback: Full traceback text of that failure, for ``--verbose`` listings.
        unresolved: ``"kind name"`` -> ``"ExcType: message"`` for each registered
            implementation that fails to import (filled by :func:`check_references`).
        refused: One line per name it registered that was refused because another plugin
            (or physinfer itself) has it; the plugin's other names work.
    """

    name: str
    distribution: str | None = None
    version: str | None = None
    module: str = ""
    error: str | None = None
    traceback: str | None = field(default=None, repr=False)
    unresolved: dict[str, str] = field(default_factory=dict)
    refused: list[str] = field(default_factory=list)


def disabled_plugins() -> set[str]:
    """Names listed in ``PHYSINFER_DISABLED_PLUGINS``."""
    return {n.strip() for n in os.environ.get(DISABLED_ENV, "").split(",") if n.strip()}


def get_plugin_manager(
    *, extra_plugins: dict[str, ModuleType | Any] | None = None, load_entry_points: bool = True
) -> tuple[pluggy.PluginManager, dict[str, PluginInfo]]:
    """Create a fresh plugin manager (no module-global state).

    Args:
        extra_plugins: Plugin objects to register directly by name (tests, notebooks).
        load_entry_points: Whether to load the ``physinfer`` entry-point group.

    Returns:
        The manager and a :class:`PluginInfo` per plugin seen (loaded or failed).
    """
    pm = pluggy.PluginManager(hooks.PROJECT_NAME)
    pm.add_hookspecs(hooks)
    infos: dict[str, PluginInfo] = {}
    blocked = disabled_plugins()
    for name in blocked:
        pm.set_blocked(name)
    if load_entry_points:
        for ep in sorted(metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
            if ep.name in blocked or ep.name in infos:
                continue
            dist = getattr(ep, "dist", None)
            info = PluginInfo(
                name=ep.name,
                distribution=dist.metadata["Name"] if dist is not None else None,
                version=dist.version if dist is not None else None,
                module=ep.value,
            )
            infos[ep.name] = info
            try:
                pm.register(ep.load(), name=ep.name)
            except Exception as exc:  # a broken plugin must not take the others down
                info.error = f"{type(exc).__name__}: {exc}"
                info.traceback = traceback.format_exc()
    for name, plugin in (extra_plugins or {}).items():
        if name in blocked:
            continue
        info = infos[name] = PluginInfo(name=name, module=getattr(plugin, "__name__", repr(plugin)))
        try:
            pm.register(plugin, name=name)
        except Exception as exc:  # a hook whose arguments do not match its specification
            info.error = f"{type(exc).__name__}: {exc}"
            info.traceback = traceback.format_exc()
    _drop_unknown_hooks(pm, infos)
    pm.check_pending()
    return pm, infos


def _drop_unknown_hooks(pm: pluggy.PluginManager, infos: dict[str, PluginInfo]) -> None:
    """Unregister, with their error, plugins implementing a hook physinfer has no spec for.

    pluggy's ``check_pending`` would raise for the first such hook and take every command
    down with it; a misspelled hook is the plugin's fault and stays the plugin's problem.
    """
    known = [
        name
        for name in vars(pm.hook)
        if not name.startswith("_") and getattr(pm.hook, name).has_spec()
    ]
    for name in sorted(vars(pm.hook)):
        caller = getattr(pm.hook, name)
        if name.startswith("_") or caller.has_spec():
            continue
        for impl in caller.get_hookimpls():
            if impl.optionalhook or pm.get_plugin(impl.plugin_name) is None:
                continue
            close = difflib.get_close_matches(name, known, n=1)
            hint = (
                f" (did you mean {close[0]!r}?)"
                if close
                else f" (known hooks: {', '.join(sorted(known))})"
            )
            info = infos.setdefault(impl.plugin_name, PluginInfo(name=impl.plugin_name))
            info.error = f"PluginValidationError: unknown hook {name!r}{hint}"
            pm.unregister(name=impl.plugin_name)


def check_references(registry: Registry, infos: dict[str, PluginInfo]) -> None:
    """Import every registered ``"module:attr"`` and record those that fail in ``infos``.

    Registration names implementations lazily, so a plugin whose module has a broken import
    registers fine and fails only when used; this finds it beforehand (``physinfer
    plugins``). It imports every plugin's implementation modules, heavy libraries included.
    """
    for kind in KINDS:
        for entry in registry.entries[kind].values():
            try:
                entry.load()
            except Exception as exc:
                info = infos.setdefault(entry.plugin, PluginInfo(name=entry.plugin))
                cause = exc.__cause__ or exc
                info.unresolved[f"{entry.kind_label} {entry.name}"] = (
                    f"{type(cause).__name__}: {cause}"
                )


def load_registry(
    pm: pluggy.PluginManager | None = None,
    infos: dict[str, PluginInfo] | None = None,
    *,
    extra_plugins: dict[str, Any] | None = None,
    load_entry_points: bool = True,
) -> tuple[Registry, dict[str, PluginInfo]]:
    """Call every registration hook, plugin by plugin, into a new :class:`Registry`.

    A plugin whose hook raises is marked with its error and what it registered before
    failing is kept out of the way of nothing else. The host's plugins are called first
    (:data:`HOST_DISTRIBUTION`), so a name a third party also registers stays the host's.
    """
    if pm is None:
        pm, infos = get_plugin_manager(
            extra_plugins=extra_plugins, load_entry_points=load_entry_points
        )
    infos = infos if infos is not None else {}
    registry = Registry()

    def rank(plugin: str) -> int:
        return 0 if infos.get(plugin) and infos[plugin].distribution == HOST_DISTRIBUTION else 1

    for hook_name in REGISTER_HOOKS:
        caller = getattr(pm.hook, hook_name)
        impls = caller.get_hookimpls()
        order = sorted(range(len(impls)), key=lambda i: (rank(impls[i].plugin_name), i))
        for impl in (impls[i] for i in order):
            plugin = impl.plugin_name
            if infos.get(plugin) is not None and infos[plugin].error:
                continue
            try:
                impl.function(registry=registry.scoped(plugin))
            except Exception as exc:
                info = infos.setdefault(plugin, PluginInfo(name=plugin))
                info.error = f"{type(exc).__name__} in {hook_name}: {exc}"
                info.traceback = traceback.format_exc()
    registry.errors.update({name: info.error for name, info in infos.items() if info.error})
    for plugin, lines in registry.refused.items():
        infos.setdefault(plugin, PluginInfo(name=plugin)).refused = lines
    return registry, infos
