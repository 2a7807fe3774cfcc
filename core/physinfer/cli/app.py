"""The ``physinfer`` command line (typer): where its commands are assembled.

Every command that computes a result takes ``--json`` and then prints exactly one JSON
object on stdout; progress and logs go to stderr. User mistakes end with one line on
stderr (and ``{"error": ...}`` on stdout with ``--json``) and exit status 2; anything
else is a bug and ends with one line naming it and the file its traceback was saved to
(in the system's temporary directory, never in ``--out``), exit status 1. Both go through
:func:`handle_errors`. ``physinfer --help`` stays fast: commands call the library through the
package's face (``physinfer.refine``, ...), which imports the API on first use, and the few
modules that would load a heavy library or a whole workflow are imported inside the command
that needs them.

The host's own commands live beside this module (``plugins_cmd``, ``simulate_cmd``,
``refine_cmd`` here; ``diagnose_cmd``, ``posterior_cmd``, ``prepare_cmd``, ``render_cmd``,
``report_cmd``, ``dataset_cmd`` through the ``physinfer_register_commands`` hook, as a
plugin's are), the shared options in :mod:`physinfer.cli.options` and the error path in
:mod:`physinfer.cli.common`; their names are re-exported here, where commands and plugins
have imported them from.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

import typer

from physinfer.cli.common import (
    _TYPER_FLOW,
    TRACEBACK_DIR,
    JsonAwareGroup,
    emit_json,
    handle_errors,
    registry_and_infos,
    report_internal_error,
    say_error,
)
from physinfer.cli.options import (
    CLI_ONLY,
    CLI_RENAMES,
    BatchSizeOpt,
    DiagnoseBatchSizeOpt,
    DurationOpt,
    EmbedderFramesOpt,
    EndOpt,
    FixOpt,
    JsonOpt,
    MirrorOpt,
    NoPrepareOpt,
    PluginOpt,
    RoiOpt,
    SceneSetOpt,
    SeedOpt,
    SelectSeedsOpt,
    SelectTopOpt,
    StartOpt,
    options_from_cli,
    parse_render_set,
)
from physinfer.cli.plugins_cmd import plugins_cmd
from physinfer.cli.refine_cmd import (
    NOISE_RATIO_HINT,
    best_fit_line,
    noise_ratio_hint,
    posterior_source_line,
    refine_cmd,
    refine_result_lines,
)
from physinfer.cli.simulate_cmd import simulate_cmd
from physinfer.console import err_console
from physinfer.plugins import PluginInfo, disabled_plugins
from physinfer.registry import Entry, Registry

__all__ = [
    "CLI_ONLY",
    "CLI_RENAMES",
    "NOISE_RATIO_HINT",
    "TRACEBACK_DIR",
    "BatchSizeOpt",
    "DiagnoseBatchSizeOpt",
    "DurationOpt",
    "EmbedderFramesOpt",
    "FixOpt",
    "JsonOpt",
    "NoPrepareOpt",
    "PluginOpt",
    "MirrorOpt",
    "StartOpt",
    "EndOpt",
    "RoiOpt",
    "SceneSetOpt",
    "SeedOpt",
    "SelectSeedsOpt",
    "SelectTopOpt",
    "app",
    "best_fit_line",
    "emit_json",
    "err_console",
    "handle_errors",
    "mounted_app",
    "noise_ratio_hint",
    "options_from_cli",
    "parse_render_set",
    "posterior_source_line",
    "refine_result_lines",
    "registry_and_infos",
    "report_internal_error",
    "run",
]

app = typer.Typer(
    name="physinfer",
    help="Measure physical parameters from video by refining simulations until they match.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    cls=JsonAwareGroup,
)

# The host's own commands, in the order `physinfer --help` lists them (plugins' come after);
# physinfer.registry.HOST_COMMANDS names them, so no plugin can register one.
app.command("plugins")(plugins_cmd)
app.command("simulate")(simulate_cmd)
app.command("refine")(refine_cmd)


# ------------------------------------------------------------- plugin-registered commands


def _mount_plugin_commands() -> None:
    """Add commands registered through ``physinfer_register_commands``; skip broken ones.

    A name with a space, ``"evaluate triplets"``, is a subcommand of the group named by its
    first word; the group is created when no plugin registers it, so several plugins can
    contribute subcommands to one group (``physinfer evaluate triplets|wind|bouman``).
    A subcommand the group has already (``dataset generate`` of the built-in ``dataset``
    group) or one under a command that is not a group is refused, listed for its plugin by
    ``physinfer plugins``, and the command that was there keeps working.
    """
    registry, infos = registry_and_infos()
    groups: dict[str, typer.Typer] = {}
    for name, entry in sorted(registry.entries["commands"].items()):
        parent_name, _, child = name.partition(" ")
        why = _subcommand_clash(parent_name, child, groups, registry)
        if why is not None:
            _refuse_command(registry, infos, entry, why)
            continue
        try:
            obj = entry.load()
        except Exception as exc:  # the command says why when run; --help and the rest work
            obj = _broken_command(exc)
        parent = app
        if child:
            parent = groups.get(parent_name) or _new_group(parent_name, groups)
            name = child
        if isinstance(obj, typer.Typer):
            wrap_plugin_group(obj)
            parent.add_typer(obj, name=name, help=entry.description or None)
            if parent is app:
                groups[name] = obj
        else:  # the CLI's one error path, whether or not the plugin decorated its command
            settings = getattr(obj, "context_settings", None)  # a broken command takes any option
            command = parent.command(
                name, help=entry.description or None, context_settings=settings
            )
            command(handle_errors()(obj))


def wrap_plugin_group(group: typer.Typer) -> None:
    """Give every command of a plugin's own ``typer.Typer`` (and of its sub-groups) the one
    error path, as a plugin's single commands get it when mounted (:func:`handle_errors`).
    A command already wrapped is left as it is."""
    for info in group.registered_commands:
        if info.callback is not None and not getattr(info.callback, "_physinfer_errors", False):
            info.callback = handle_errors()(info.callback)
    for sub in group.registered_groups:
        if sub.typer_instance is not None:
            wrap_plugin_group(sub.typer_instance)


def _subcommand_clash(
    parent_name: str, child: str, groups: dict[str, typer.Typer], registry: Registry
) -> str | None:
    """Why the subcommand ``parent_name child`` cannot be mounted, or ``None``."""
    if not child:
        return None
    group = groups.get(parent_name)
    if group is None:
        parent = registry.entries["commands"].get(parent_name)
        if parent is not None:  # registered, yet not mounted as a group: a plain command
            return f"{parent_name!r} is a command of plugin {parent.plugin!r}, not a group"
        return None
    taken = {
        info.name or typer.main.get_command_name(info.callback.__name__)
        for info in group.registered_commands
        if info.callback is not None
    }
    taken |= {info.name for info in group.registered_groups if info.name}
    if child in taken:
        return f"the group {parent_name!r} has that command already"
    return None


def _refuse_command(
    registry: Registry, infos: dict[str, PluginInfo], entry: Entry, why: str
) -> None:
    """Leave ``entry`` out of the CLI and list it as refused for its plugin."""
    registry.refuse(entry.plugin, f"command {entry.name!r}", why)
    registry.entries["commands"].pop(entry.name, None)
    info = infos.setdefault(entry.plugin, PluginInfo(name=entry.plugin))
    info.refused = registry.refused[entry.plugin]


def _broken_command(error: Exception) -> Callable[..., None]:
    """A stand-in for a plugin command that fails to import: running it prints ``error``."""

    def broken(as_json: JsonOpt = False) -> None:
        raise error

    broken.__doc__ = "[unavailable: its plugin is broken; see `physinfer plugins`]"
    settings = {"ignore_unknown_options": True, "allow_extra_args": True}
    broken.context_settings = settings  # type: ignore[attr-defined]
    return broken


def _new_group(name: str, groups: dict[str, typer.Typer]) -> typer.Typer:
    """An empty command group ``physinfer NAME`` for plugin subcommands."""
    group = typer.Typer(no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False)
    app.add_typer(group, name=name, help=f"{name.capitalize()} commands contributed by plugins.")
    groups[name] = group
    return group


_MOUNTED: list[typer.Typer] = []


def mounted_app() -> typer.Typer:
    """The whole CLI, plugin commands included, mounted once per process.

    For running commands in-process (``typer.testing.CliRunner().invoke(mounted_app(), [...])``)
    without a new interpreter's start-up.
    """
    if app not in _MOUNTED:
        _mount_plugin_commands()
        _MOUNTED.append(app)
    return app


def refuse_unknown_command(cli: typer.Typer, argv: list[str]) -> None:
    """An unknown command word: one ``error:`` line (one JSON object with ``--json``), exit 2.

    Typer would print a usage box and no JSON. The line names the closest command and the
    plugins ``PHYSINFER_DISABLED_PLUGINS`` blocks, whose commands are missing on purpose.
    """
    import difflib

    words = [arg for arg in argv if not arg.startswith("-")]
    commands = typer.main.get_group(cli).commands
    if not words or words[0] in commands:
        return
    message = f"no such command {words[0]!r}"
    close = difflib.get_close_matches(words[0], list(commands), n=1)
    message += f" (did you mean {close[0]!r}?)" if close else ""
    blocked = sorted(disabled_plugins())
    if blocked:
        message += f"; PHYSINFER_DISABLED_PLUGINS={','.join(blocked)} blocks those plugins and their commands"
    say_error(f"{message}; see `physinfer --help`")
    if "--json" in argv:
        emit_json({"error": message})
    sys.exit(2)


def run() -> None:
    """Entry point of the ``physinfer`` console script.

    Failures outside a command's :func:`handle_errors` (mounting plugin commands, a plugin's
    command group of its own) take the same internal-error path.
    """
    try:
        refuse_unknown_command(mounted_app(), sys.argv[1:])
        mounted_app()()
    except _TYPER_FLOW:
        raise
    except Exception as exc:
        report_internal_error(exc, as_json="--json" in sys.argv[1:])
        sys.exit(1)
