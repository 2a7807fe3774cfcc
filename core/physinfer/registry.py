"""The registry that plugins fill through hooks, with lazy ``"module:attr"`` references.

Entries remember which plugin added them, so ``physinfer plugins`` can show who
provides what, and resolve their implementation only when first used. A name is registered
once: a plugin that adds a name already taken (by the host's plugins, which register first,
or by another plugin before it), or a command named like one of physinfer's own
(:data:`HOST_COMMANDS`), has that one entry refused and listed in :attr:`Registry.refused`;
the first holder keeps working and the rest of the plugin loads.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from physinfer.errors import PhysinferError, UserInputError

#: The commands physinfer itself defines (``physinfer.cli.app``, in ``--help``'s order): no
#: plugin may register one of these names or a subcommand under it.
HOST_COMMANDS = ("plugins", "simulate", "refine")

KINDS = ("phenomena", "optimizers", "embedders", "effects", "commands")
#: How one entry of each kind is named in messages.
KIND_LABELS = {
    "phenomena": "phenomenon",
    "optimizers": "optimizer",
    "embedders": "embedder",
    "effects": "effect",
    "commands": "command",
}


class PluginLoadError(PhysinferError):
    """A plugin's registered implementation cannot be imported (the plugin is broken).

    Not the user's input but their environment: the CLI says it in one line naming the
    plugin, like a user error, and every other plugin keeps working.
    """


def resolve(ref: str | Callable[..., Any]) -> Any:
    """Import a ``"package.module:attr"`` reference (callables pass through)."""
    if not isinstance(ref, str):
        return ref
    module_name, sep, attr = ref.partition(":")
    if not sep:
        raise ValueError(f"reference {ref!r} must look like 'package.module:attr'")
    obj: Any = importlib.import_module(module_name)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


@dataclass
class Entry:
    """One registered thing.

    Attributes:
        name: Its name (unique within its kind).
        factory: ``"module:attr"`` or callable producing the implementation.
        description: One line for listings.
        plugin: Name of the plugin that registered it.
        extra: Kind-specific metadata (``phenomenon`` for effects).
        kind: One of :data:`KINDS`.
    """

    name: str
    factory: str | Callable[..., Any]
    description: str = ""
    plugin: str = ""
    extra: dict[str, Any] = field(default_factory=dict)
    kind: str = ""

    @property
    def kind_label(self) -> str:
        """``"phenomenon"``, ``"effect"``, ... for messages."""
        return KIND_LABELS.get(self.kind, "entry")

    def load(self) -> Any:
        """Resolve the factory reference.

        Raises:
            PluginLoadError: the reference cannot be imported; one line naming the plugin,
                what it registered and why (the original exception is its ``__cause__``).
        """
        try:
            return resolve(self.factory)
        except Exception as exc:
            text = " ".join(str(exc).split())
            raise PluginLoadError(
                f"plugin {self.plugin!r} is broken: its {self.kind_label} {self.name!r} ({self.factory}) "
                f"fails to import ({type(exc).__name__}: {text}); fix or reinstall the plugin, or block it "
                f"with PHYSINFER_DISABLED_PLUGINS={self.plugin} (`physinfer plugins` lists what is broken)"
            ) from exc


class Registry:
    """All phenomena, optimizers, embedders, effects and commands of the loaded plugins."""

    def __init__(self) -> None:
        self.entries: dict[str, dict[str, Entry]] = {kind: {} for kind in KINDS}
        self.errors: dict[str, str] = {}
        #: Plugin name -> one line per name it registered that was refused (already taken).
        self.refused: dict[str, list[str]] = {}
        self._plugin = ""

    def scoped(self, plugin: str) -> Registry:
        """A view whose ``add_*`` calls are attributed to ``plugin``."""
        view = object.__new__(Registry)
        view.entries, view.errors, view.refused = self.entries, self.errors, self.refused
        view._plugin = plugin
        return view

    def _add(self, kind: str, name: str, factory: Any, description: str, **extra: Any) -> None:
        existing = self.entries[kind].get(name)
        why = None
        if kind == "commands" and name.partition(" ")[0] in HOST_COMMANDS:
            why = "physinfer's own command has that name"
        elif existing is not None:
            why = f"plugin {existing.plugin!r} registered it first"
        if why is not None:  # the first holder keeps the name; this plugin's other names load
            self.refuse(self._plugin, f"{KIND_LABELS[kind]} {name!r}", why)
            return
        self.entries[kind][name] = Entry(
            name, factory, description, self._plugin, dict(extra), kind
        )

    def refuse(self, plugin: str, what: str, why: str) -> None:
        """Record that ``plugin``'s ``what`` (``"command 'simulate'"``) was refused, and why."""
        line = f"{what} refused: {why} (rename it in this plugin)"
        self.refused.setdefault(plugin, []).append(line)

    def add_phenomenon(
        self, name: str, factory: str | Callable[[], Any], description: str = ""
    ) -> None:
        """Register a phenomenon; ``factory()`` returns a :class:`~physinfer.roles.Phenomenon`."""
        self._add("phenomena", name, factory, description)

    def add_optimizer(
        self, name: str, factory: str | Callable[..., Any], description: str = ""
    ) -> None:
        """Register an optimizer; ``factory(dim=, seed=, names=)`` returns an Optimizer."""
        self._add("optimizers", name, factory, description)

    def add_embedder(
        self, name: str, factory: str | Callable[..., Any], description: str = ""
    ) -> None:
        """Register an embedder; ``factory(model=None, device=None)`` returns an Embedder."""
        self._add("embedders", name, factory, description)

    def add_effect(
        self, name: str, factory: str | Callable[[], Any], phenomenon: str, description: str = ""
    ) -> None:
        """Register an effect of ``phenomenon``; ``factory()`` returns an Effect."""
        self._add("effects", name, factory, description, phenomenon=phenomenon)

    def add_command(
        self, name: str, factory: str | Callable[..., Any], description: str = ""
    ) -> None:
        """Register a CLI command (a ``typer.Typer`` group or a function)."""
        self._add("commands", name, factory, description)

    # -- lookup -----------------------------------------------------------------------

    def get(self, kind: str, name: str) -> Entry:
        """The entry ``name`` of ``kind``, or a :class:`UserInputError` listing what exists."""
        try:
            return self.entries[kind][name]
        except KeyError:
            known = ", ".join(sorted(self.entries[kind])) or "none"
            hint = ""
            if kind == "phenomena" and self.errors:
                hint = " (plugins that failed to load: " + ", ".join(sorted(self.errors)) + ")"
            label = {"phenomena": "plugin/phenomenon"}.get(kind, kind[:-1])
            raise UserInputError(f"unknown {label} {name!r}; installed: {known}{hint}") from None

    def phenomenon(self, name: str) -> Any:
        """Build the :class:`~physinfer.roles.Phenomenon` called ``name``."""
        return self.get("phenomena", name).load()()

    def optimizer(self, name: str, **kwargs: Any) -> Any:
        """Build the optimizer called ``name``."""
        return self.get("optimizers", name).load()(**kwargs)

    def embedder(self, name: str, **kwargs: Any) -> Any:
        """Build the embedder called ``name``."""
        return self.get("embedders", name).load()(**kwargs)

    def effect(self, name: str, phenomenon: str | None = None) -> Any:
        """Build the effect called ``name``, checking it belongs to ``phenomenon``."""
        entry = self.get("effects", name)
        if phenomenon is not None and entry.extra.get("phenomenon") != phenomenon:
            known = ", ".join(self.effects_of(phenomenon)) or "none"
            raise UserInputError(
                f"effect {name!r} belongs to {entry.extra.get('phenomenon')!r}, not {phenomenon!r}; "
                f"effects of {phenomenon!r}: {known}"
            )
        return entry.load()()

    def effects_of(self, phenomenon: str) -> list[str]:
        """Names of the effects registered for ``phenomenon``."""
        return sorted(
            n for n, e in self.entries["effects"].items() if e.extra.get("phenomenon") == phenomenon
        )

    def by_plugin(self, plugin: str) -> dict[str, list[str]]:
        """What ``plugin`` registered, by kind."""
        return {
            kind: sorted(n for n, e in self.entries[kind].items() if e.plugin == plugin)
            for kind in KINDS
        }


def accepts_keyword(factory: Any, name: str) -> bool:
    """Whether ``factory`` (a function or class) accepts the keyword argument ``name``.

    Optional plugin capabilities are keywords of their factories (``make_simulator``'s
    ``duration_s``, a parameter-free embedder's ``n_frames``).
    """
    try:
        return name in inspect.signature(factory).parameters
    except (TypeError, ValueError):  # builtins and some callables have no signature
        return False
