"""``physinfer plugins``: the installed plugins, what each provides, the broken ones with
their error, and the names each was refused because another plugin (or physinfer) has them."""

from __future__ import annotations

from typing import Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape

from physinfer.cli.common import emit_json, handle_errors, registry_and_infos
from physinfer.cli.options import JsonOpt
from physinfer.console import err_console
from physinfer.plugins import check_references
from physinfer.scene import scene_settings_of


@handle_errors()
def plugins_cmd(
    as_json: JsonOpt = False,
    verbose: Annotated[
        bool, typer.Option("--verbose", "-v", help="Show tracebacks of broken plugins.")
    ] = False,
) -> None:
    """List installed plugins and what each provides; broken plugins with their error.

    Imports every implementation the plugins name, so one that fails to import shows here;
    a name a plugin registered that physinfer or another plugin has already is listed as refused.
    """
    registry, infos = registry_and_infos()
    check_references(registry, infos)
    rows = _plugin_rows(registry, infos)
    for r in rows:  # in full on stderr (the table's cells may be cut to the terminal's width)
        if r["error"] or r["unresolved"] or r["refused"]:
            status = _plugin_status(r["error"], r["unresolved"], r["refused"])
            err_console.print(f"plugin {r['name']!r}: {status}", highlight=False)
    if as_json:
        emit_json(
            {
                "plugins": rows,
                "phenomena": sorted(registry.entries["phenomena"]),
                "scene_settings": _scene_settings(registry),
            }
        )
        return
    Console().print(_plugins_table(rows))
    if verbose:
        for name, info in infos.items():
            if info.traceback:
                err_console.print(f"[bold]{name}[/]\n{info.traceback}", highlight=False)


def _plugin_rows(registry: Any, infos: dict[str, Any]) -> list[dict[str, Any]]:
    """A row per plugin, by name: where it comes from, what it provides, what failed."""
    rows = []
    for name, info in sorted(infos.items()):
        provided = registry.by_plugin(name)
        rows.append(
            {
                "name": name,
                "distribution": info.distribution,
                "version": info.version,
                "module": info.module,
                "phenomena": provided["phenomena"],
                "optimizers": provided["optimizers"],
                "embedders": provided["embedders"],
                "effects": provided["effects"],
                "commands": provided["commands"],
                "error": info.error,
                "unresolved": info.unresolved,
                "refused": info.refused,
            }
        )
    return rows


def _plugins_table(rows: list[dict[str, Any]]) -> Any:
    """The table ``physinfer plugins`` prints (a rich ``Table``)."""
    from rich.table import Table

    table = Table(title="physinfer plugins")
    for col in (
        "plugin",
        "distribution",
        "phenomena",
        "optimizers",
        "embedders",
        "effects",
        "status",
    ):
        table.add_column(col)
    for r in rows:
        table.add_row(
            r["name"],
            f"{r['distribution'] or '-'} {r['version'] or ''}".strip(),
            ", ".join(r["phenomena"]),
            ", ".join(r["optimizers"]),
            ", ".join(r["embedders"]),
            ", ".join(r["effects"]),
            _plugin_status(r["error"], r["unresolved"], r["refused"]),
        )
    return table


def _scene_settings(registry: Any) -> dict[str, list[dict[str, Any]]]:
    """Each loadable phenomenon's scene settings (``--scene-set``), as JSON; broken ones are
    reported in the plugin rows instead."""
    out: dict[str, list[dict[str, Any]]] = {}
    for name in sorted(registry.entries["phenomena"]):
        try:
            phenomenon = registry.phenomenon(name)
        except Exception:  # noqa: BLE001 - a broken plugin shows in its row
            continue
        out[name] = [setting.to_dict() for setting in scene_settings_of(phenomenon).values()]
    return out


def _plugin_status(
    error: str | None, unresolved: dict[str, str], refused: list[str] | None = None
) -> str:
    """The status cell of ``physinfer plugins``: ``ok``, or what failed, in red."""
    problems = ([error] if error else []) + [f"{what}: {why}" for what, why in unresolved.items()]
    problems += refused or []
    return "[red]" + escape("; ".join(problems)) + "[/]" if problems else "ok"
