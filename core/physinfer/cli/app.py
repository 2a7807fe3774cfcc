"""The ``physinfer`` command line (typer).

Every command that computes a result takes ``--json`` and then prints exactly one JSON
object on stdout; progress and logs go to stderr. User mistakes end with one line on
stderr (and ``{"error": ...}`` on stdout with ``--json``) and exit status 2; anything
else is a bug and ends with one line naming it and the file its traceback was saved to
(in the system's temporary directory, never in ``--out``), exit status 1. Both go through
:func:`handle_errors`. Heavy libraries are imported inside commands, so ``physinfer
--help`` stays fast.
"""

from __future__ import annotations

import functools
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape
from typer.exceptions import TyperException

from physinfer.console import err_console
from physinfer.errors import PhysinferError, UserInputError

app = typer.Typer(
    name="physinfer",
    help="Measure physical parameters from video by refining simulations until they match.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

JsonOpt = Annotated[bool, typer.Option("--json", help="Print exactly one JSON object on stdout.")]
PluginOpt = Annotated[str, typer.Option("--plugin", "-p", help="Phenomenon to use (see `physinfer plugins`).")]
SeedOpt = Annotated[int, typer.Option("--seed", help="Seed of the optimizer and of every simulation.")]
SelectTopOpt = Annotated[
    int,
    typer.Option(
        "--select-top",
        help="Re-simulate the M best trials under --select-seeds fresh seeds and keep the one with the lowest "
        "mean distance (0: the lowest logged distance; 4 suits chaotic phenomena such as the flag).",
    ),
]
SelectSeedsOpt = Annotated[int, typer.Option("--select-seeds", help="Fresh seeds per finalist of --select-top.")]
DurationOpt = Annotated[
    float | None,
    typer.Option(
        "--duration",
        help="Seconds every simulation records (default: the plugin's; the flag's 2.4 s). Longer clips "
        "are for an embedder that reads more frames (--embedder-frames, or an SDN trained on them).",
    ),
]
FixOpt = Annotated[
    list[str],
    typer.Option(
        "--fix",
        help="Hold a parameter at a known value and leave it out of the search: NAME=VALUE, "
        "NAME may be a pattern such as 'bend_*' (repeatable).",
    ),
]
EmbedderFramesOpt = Annotated[
    int | None,
    typer.Option(
        "--embedder-frames",
        help="Frames a parameter-free embedder reads (the flag's spectral: default 30; e.g. 200 "
        "with --duration 8). An SDN's frames are set by its weights.",
    ),
]
SceneSetOpt = Annotated[
    list[str],
    typer.Option(
        "--scene-set",
        help="A known setting of the scene, not inferred: NAME=VALUE (repeatable). The flag: flag_length, "
        "flag_height, pole_height (m), pinning=hoist|corners; the hanging cloth: cloth_width, "
        "cloth_height (m), fan=W1|W2|W3. A wrong name lists the plugin's; `physinfer plugins --json` lists "
        "every phenomenon's (scene_settings).",
    ),
]
NoPrepareOpt = Annotated[
    bool,
    typer.Option(
        "--no-prepare",
        help="Use --target as it is. By default a video that is not square is framed as the renderer "
        "frames its subject, steadied and resampled first (as `physinfer prepare` does).",
    ),
]
RoiOpt = Annotated[
    str | None,
    typer.Option("--roi", help="x,y,w,h: the region the subject moves in, in --target's pixels (instead of the one found)."),
]
BatchSizeOpt = Annotated[
    int,
    typer.Option(
        "--batch-size",
        help="Trials proposed per optimizer step and simulated as one batch (q); the flag simulates "
        "a batch in parallel threads. Same --steps budget, fewer optimizer rounds.",
    ),
]


@functools.cache
def registry_and_infos() -> tuple[Any, Any]:
    """The registry of all installed plugins, built once per process."""
    from physinfer.plugins import load_registry

    return load_registry()


def emit_json(obj: Any) -> None:
    """Print one JSON object on stdout."""
    from physinfer.io import to_jsonable

    sys.stdout.write(json.dumps(to_jsonable(obj), allow_nan=False) + "\n")
    sys.stdout.flush()


#: Exceptions typer uses for control flow (exit codes, usage errors): never internal errors.
_TYPER_FLOW = (typer.Exit, typer.Abort, TyperException)
#: Sub-folder of the system's temporary directory that holds saved tracebacks.
TRACEBACK_DIR = "physinfer-errors"


def handle_errors(
    as_json_param: str = "as_json",
    interrupted: str = "interrupted; completed trials are saved — continue with --resume",
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Give a command the one error path of the CLI.

    A user error (:class:`UserInputError`, :class:`PhysinferError`) is one clear line and
    exit status 2; any other exception is one line naming it and a saved traceback, exit
    status 1 (:func:`report_internal_error`). With ``--json`` either prints one
    ``{"error": ...}`` object on stdout.

    Args:
        as_json_param: The command's keyword argument that is ``--json``.
        interrupted: What to say on Ctrl-C (exit status 130).
    """

    def decorate(func: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(func)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            as_json = bool(kwargs.get(as_json_param))
            try:
                return func(*args, **kwargs)
            except (UserInputError, PhysinferError) as exc:
                err_console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
                if as_json:
                    emit_json({"error": str(exc)})
                raise typer.Exit(2) from None
            except KeyboardInterrupt:
                err_console.print(interrupted, highlight=False)
                raise typer.Exit(130) from None
            except _TYPER_FLOW:
                raise
            except Exception as exc:  # a bug: one line and a saved traceback, not a raw dump
                report_internal_error(exc, as_json=as_json)
                raise typer.Exit(1) from None

        return wrapper

    return decorate


def report_internal_error(exc: BaseException, *, as_json: bool) -> None:
    """Say ``error: internal error (ExcType: msg); traceback saved to PATH`` on one line.

    The traceback goes to ``<temp dir>/physinfer-errors/`` (``$TMPDIR`` or the system's), a
    place every command may write and none of them reads; with ``as_json`` the same message
    and the path are printed as one JSON object on stdout.
    """
    import traceback

    text = " ".join(str(exc).split())
    summary = f"{type(exc).__name__}: {text[:300]}" if text else type(exc).__name__
    path: Path | None = None
    try:
        folder = Path(tempfile.gettempdir()) / TRACEBACK_DIR
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"traceback-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.txt"
        path.write_text("".join(traceback.format_exception(exc)))
        where = f"traceback saved to {path}"
    except OSError as write_error:
        where = f"the traceback could not be saved ({write_error.strerror or write_error})"
    message = f"internal error ({summary}); {where}"
    err_console.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
    if as_json:
        emit_json({"error": message, "traceback": str(path) if path else None})


def parse_render_set(items: list[str]) -> dict[str, Any]:
    """``NAME=VALUE`` render settings; numbers become floats, ``true``/``false`` booleans."""
    from physinfer.parameters import parse_assignments

    out: dict[str, Any] = {}
    for name, raw in parse_assignments(items, "--render-set").items():
        low = raw.lower()
        if low in ("true", "false"):
            out[name] = low == "true"
            continue
        try:
            out[name] = float(raw)
        except ValueError:
            out[name] = raw
    return out


#: CLI parameters named otherwise in the API's options (``physinfer.api.options``).
CLI_RENAMES = {"effect": "effects", "set_": "set"}
#: CLI parameters that are not settings of the command.
CLI_ONLY = frozenset({"plugin", "as_json"})


def options_from_cli(kind: type, values: dict[str, Any]) -> Any:
    """The API's options object ``kind`` from a command's parameters (its ``locals()``).

    Repeated ``NAME=VALUE`` options become dicts (``--render-set``, ``--scene-set``) or
    tuples; every other parameter is a field of the same name (:data:`CLI_RENAMES` aside),
    so a CLI option without its field in the API fails at once (tests/core/test_library_api.py).
    """
    import dataclasses

    from physinfer.scene import parse_scene_set

    fields = {f.name for f in dataclasses.fields(kind)}
    settings: dict[str, Any] = {}
    for name, value in values.items():
        if name in CLI_ONLY:
            continue
        field_name = CLI_RENAMES.get(name, name)
        if field_name not in fields:
            raise TypeError(f"the CLI option {name!r} has no field in {kind.__name__}")
        if field_name == "render_set":
            value = parse_render_set(value)
        elif field_name == "scene_set":
            value = parse_scene_set(value)
        elif isinstance(value, list):
            value = tuple(value)
        settings[field_name] = value
    return kind(**settings)


# --------------------------------------------------------------------------- plugins


@app.command("plugins")
@handle_errors()
def plugins_cmd(
    as_json: JsonOpt = False,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Show tracebacks of broken plugins.")] = False,
) -> None:
    """List installed plugins and what each provides; broken plugins with their error.

    Imports every implementation the plugins name, so one that fails to import shows here.
    """
    from physinfer.plugins import check_references

    registry, infos = registry_and_infos()
    check_references(registry, infos)
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
            }
        )
    for r in rows:  # in full on stderr (the table's cells may be cut to the terminal's width)
        if r["error"] or r["unresolved"]:
            status = _plugin_status(r["error"], r["unresolved"])
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
    from rich.table import Table

    table = Table(title="physinfer plugins")
    for col in ("plugin", "distribution", "phenomena", "optimizers", "embedders", "effects", "status"):
        table.add_column(col)
    for r in rows:
        table.add_row(
            r["name"],
            f"{r['distribution'] or '-'} {r['version'] or ''}".strip(),
            ", ".join(r["phenomena"]),
            ", ".join(r["optimizers"]),
            ", ".join(r["embedders"]),
            ", ".join(r["effects"]),
            _plugin_status(r["error"], r["unresolved"]),
        )
    Console().print(table)
    if verbose:
        for name, info in infos.items():
            if info.traceback:
                err_console.print(f"[bold]{name}[/]\n{info.traceback}", highlight=False)


def _scene_settings(registry: Any) -> dict[str, list[dict[str, Any]]]:
    """Each loadable phenomenon's scene settings (``--scene-set``), as JSON; broken ones are
    reported in the plugin rows instead."""
    from physinfer.scene import scene_settings_of

    out: dict[str, list[dict[str, Any]]] = {}
    for name in sorted(registry.entries["phenomena"]):
        try:
            phenomenon = registry.phenomenon(name)
        except Exception:  # noqa: BLE001 - a broken plugin shows in its row
            continue
        out[name] = [setting.to_dict() for setting in scene_settings_of(phenomenon).values()]
    return out


def _plugin_status(error: str | None, unresolved: dict[str, str]) -> str:
    """The status cell of ``physinfer plugins``: ``ok``, or what failed, in red."""
    problems = ([error] if error else []) + [f"{what}: {why}" for what, why in unresolved.items()]
    return "[red]" + escape("; ".join(problems)) + "[/]" if problems else "ok"


# -------------------------------------------------------------------------- simulate


@app.command("simulate")
@handle_errors()
def simulate_cmd(
    plugin: PluginOpt,
    set_: Annotated[list[str], typer.Option("--set", help="Parameter value NAME=VALUE (repeatable).")] = [],  # noqa: B006
    effect: Annotated[list[str], typer.Option("--effect", help="Switch an effect in (repeatable).")] = [],  # noqa: B006
    render_set: Annotated[
        list[str], typer.Option("--render-set", help="Render setting NAME=VALUE (repeatable).")
    ] = [],  # noqa: B006
    seed: SeedOpt = 0,
    duration: DurationOpt = None,
    scene_set: SceneSetOpt = [],  # noqa: B006
    out: Annotated[Path | None, typer.Option("--out", help="Video to write (.mp4 or .gif).")] = None,
    trajectory_out: Annotated[
        Path | None, typer.Option("--trajectory-out", help="Trajectory NPZ to write.")
    ] = None,
    as_json: JsonOpt = False,
) -> None:
    """Run one simulation and render it to a video (and/or save the trajectory)."""
    given = dict(locals())
    from physinfer import api

    options = options_from_cli(api.SimulateOptions, given)
    if out is None and trajectory_out is None:
        raise UserInputError("nothing to write: give --out VIDEO and/or --trajectory-out FILE.npz")
    sim = api.simulate(plugin, options, render=out is not None)
    if as_json:
        emit_json(sim.to_dict())
    else:
        err_console.print(f"wrote {', '.join(str(p) for p in (out, trajectory_out) if p)}")


# ---------------------------------------------------------------------------- refine

#: Above this gap / noise-floor ratio the human-readable refine output suggests more search.
NOISE_RATIO_HINT = 1.5


@app.command("refine")
@handle_errors()
def refine_cmd(
    plugin: PluginOpt,
    target: Annotated[
        Path | None, typer.Option("--target", help="Video to match; default: the plugin's embedded target.")
    ] = None,
    fps: Annotated[float | None, typer.Option("--fps", help="Frame rate of --target if it cannot be read.")] = None,
    truth: Annotated[
        list[str], typer.Option("--truth", help="Known true value NAME=VALUE, for error reporting.")
    ] = [],  # noqa: B006
    steps: Annotated[int | None, typer.Option("--steps", help="Trials in all (default: the plugin's).")] = None,
    optimizer: Annotated[str, typer.Option("--optimizer", help="ax, random, cma, or a plugin's.")] = "ax",
    embedder: Annotated[str | None, typer.Option("--embedder", help="Embedder (default: the plugin's).")] = None,
    weights: Annotated[Path | None, typer.Option("--weights", help="Embedder weights file.")] = None,
    device: Annotated[str | None, typer.Option("--device", help="torch device (default: cuda if present).")] = None,
    effect: Annotated[list[str], typer.Option("--effect", help="Switch an effect in (repeatable).")] = [],  # noqa: B006
    model: Annotated[
        Path | None,
        typer.Option("--model", help="Model file from `physinfer diagnose`: its effects, warm-started from its fit."),
    ] = None,
    render_set: Annotated[
        list[str], typer.Option("--render-set", help="Render setting NAME=VALUE for simulations.")
    ] = [],  # noqa: B006
    fix: FixOpt = [],  # noqa: B006
    seed: SeedOpt = 0,
    out: Annotated[Path | None, typer.Option("--out", help="Run directory (default: runs/<plugin>-<time>).")] = None,
    resume: Annotated[bool, typer.Option("--resume", help="Continue the run in --out.")] = False,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace a finished run in --out.")] = False,
    noise_samples: Annotated[
        int,
        typer.Option(
            "--noise-samples",
            help="Re-simulate the centre under this many seeds first and tell the optimizer the "
            "spread of the distance as its noise (0: let the optimizer infer it).",
        ),
    ] = 3,
    seeds_per_trial: Annotated[
        int, typer.Option("--seeds-per-trial", help="Average each trial's distance over this many seeds.")
    ] = 1,
    floor_samples: Annotated[
        int,
        typer.Option(
            "--floor-samples", help="Re-simulate the best fit under this many seeds to report the noise floor (0: skip)."
        ),
    ] = 4,
    select_top: SelectTopOpt = 0,
    select_seeds: SelectSeedsOpt = 3,
    batch_size: BatchSizeOpt = 1,
    workers: Annotated[
        int | None,
        typer.Option(
            "--workers",
            help="Simulate and render each step's trials in K local worker processes (with --batch-size "
            "or --seeds-per-trial; 0: the same path in this process). Default: in this process.",
        ),
    ] = None,
    scheduler: Annotated[
        str | None,
        typer.Option(
            "--scheduler",
            help="Simulate and render the trials on a Dask cluster (tcp://host:8786); its workers need "
            "physinfer and the plugin installed.",
        ),
    ] = None,
    duration: DurationOpt = None,
    embedder_frames: EmbedderFramesOpt = None,
    scene_set: SceneSetOpt = [],  # noqa: B006
    posterior: Annotated[
        Path | None,
        typer.Option(
            "--posterior",
            help="Posterior estimator (`physinfer posterior train`): start the search at the target's "
            "posterior median, search the region it covers, and report the posterior refined by the "
            "trials. Default: the plugin's shipped one, where it applies.",
        ),
    ] = None,
    no_posterior: Annotated[
        bool, typer.Option("--no-posterior", help="Use no posterior estimator (a best fit only).")
    ] = False,
    no_prepare: NoPrepareOpt = False,
    roi: RoiOpt = None,
    no_render_estimate: Annotated[
        bool,
        typer.Option(
            "--no-render-estimate",
            help="Render simulations at the default camera instead of the one estimated from --target "
            "(--render-set overrides either way).",
        ),
    ] = False,
    as_json: JsonOpt = False,
) -> None:
    """Refine a simulation until it matches a target video; report the parameters found."""
    given = dict(locals())
    from physinfer import api

    result = api.refine(plugin, options_from_cli(api.RefineOptions, given), progress=True)
    summary = result.summary()
    if as_json:
        emit_json(summary)
        return
    for line in refine_result_lines(result):
        err_console.print(line, highlight=False)


def refine_result_lines(result: Any) -> list[str]:
    """What ``refine`` prints (without ``--json``): the parameters the video determines with
    best fit, posterior median, 90 % interval and label; the others named on one line (their
    best fit is where the search stopped, and a bound it stopped on says nothing either);
    correlations, where the posterior came from, fixed values, bounds, the noise-floor hint."""
    lines = [f"best distance {result.best_distance:.4g} at step {result.best_step}"]
    if result.extra.get("scene"):
        from physinfer.scene import scene_text

        lines.append(f"  scene: {scene_text(result.extra['scene'])}")
    marginals = result.extra.get("posterior") or {}
    hidden = [n for n in result.best_params if marginals.get(n, {}).get("label") == "not identified"]
    at_bounds = {n: b for n, b in result.extra.get("at_bounds", {}).items() if n not in hidden}
    for name, value in result.best_params.items():
        if name not in hidden:
            lines.append(best_fit_line(name, value, result, marginals.get(name), at_bounds.get(name)))
    if hidden:
        names = ", ".join(hidden) if len(hidden) <= 6 else f"{', '.join(hidden[:4])}, … ({len(hidden)} in all)"
        lines.append(
            f"  not identified (the video barely narrows their ranges; best fits and intervals in "
            f"result.json): {names}"
        )
    for pair in (result.extra.get("correlations") or [])[:2]:
        lines.append(f"  correlated: {pair['a']} ~ {pair['b']}  r = {pair['r']:+.2f}")
    if result.extra.get("posterior_note"):
        lines.append(result.extra["posterior_note"])
    if result.extra.get("posterior_source"):
        lines.append(posterior_source_line(result.extra["posterior_source"]))
    for name, value in result.extra.get("fixed", {}).items():
        lines.append(f"  {name} = {value:.4g}   (fixed)")
    if at_bounds:
        lines.append(
            f"{', '.join(at_bounds)} ended on a bound of the search range: the truth may lie beyond it, "
            "or another parameter is compensating for something the model lacks (`physinfer diagnose`)."
        )
    hint = noise_ratio_hint((result.extra.get("noise_floor") or {}).get("ratio"))
    if hint:
        lines.append(hint)
    lines.append(f"results in {result.run_dir}")
    return lines


def best_fit_line(name: str, value: float, result: Any, marginal: dict | None, bound: str | None) -> str:
    """One printed parameter: the best fit and, with a posterior, its 90 % interval and label.

    A parameter the video does not determine gets no error against the truth: its best fit
    is wherever the search stopped, not a measurement.
    """
    line = f"  {name} = {value:.4g}"
    if marginal is not None:
        lo, hi = marginal["ci90"]
        line += f"   posterior {marginal['median']:.4g} [90 %: {lo:.4g} – {hi:.4g}]   {marginal['label']}"
    truth, errors = result.ground_truth or {}, result.abs_errors or {}
    if name in errors and (marginal is None or marginal["label"] != "not identified"):
        line += f"   (truth {truth[name]:.4g}, error {errors[name]:.3g})"
    elif name in truth:
        line += f"   (truth {truth[name]:.4g})"
    if bound:
        line += f"   (at its {bound} bound)"
    return line


def posterior_source_line(source: dict) -> str:
    """Where the printed intervals come from: the refinement's trials or the estimator alone."""
    estimator = Path(source["estimator"]).name
    if source["kind"] == "refined":
        return (
            f"posterior: refined by this run's trials (a likelihood of the distance over "
            f"{', '.join(source['modelled'])}; the noise floor sets its scale), from {estimator}"
        )
    return f"posterior: {estimator} alone (not refined: {source.get('not_refined', 'no trials used')})"


def noise_ratio_hint(ratio: float | None) -> str | None:
    """Advice when the best fit's gap is well above the noise floor, else ``None``.

    On held-out flag targets, fits that ended within the flag's chaos had ratios of 0.4–1.2;
    the searches that stopped short ended at 1.4–2.8 (docs/benchmarks.md, Refinement).
    """
    if ratio is None or ratio <= NOISE_RATIO_HINT:
        return None
    return (
        f"noise ratio {ratio:.2f}: the best fit is further from the target than re-simulations of itself are "
        "from each other. Refine longer (--resume --steps N) or again with another --seed; if it stays, "
        "`physinfer diagnose` looks for what the model lacks."
    )


# ------------------------------------------------------------- plugin-registered commands


def _mount_plugin_commands() -> None:
    """Add commands registered through ``physinfer_register_commands``; skip broken ones.

    A name with a space, ``"evaluate triplets"``, is a subcommand of the group named by its
    first word; the group is created when no plugin registers it, so several plugins can
    contribute subcommands to one group (``physinfer evaluate triplets|wind|bouman``).
    """
    registry, infos = registry_and_infos()
    groups: dict[str, typer.Typer] = {}
    for name, entry in sorted(registry.entries["commands"].items()):
        try:
            obj = entry.load()
        except Exception as exc:  # the command says why when run; --help and the rest work
            obj = _broken_command(exc)
        parent_name, _, child = name.partition(" ")
        parent = app
        if child:
            parent = groups.get(parent_name) or _new_group(parent_name, groups)
            name = child
        if isinstance(obj, typer.Typer):
            parent.add_typer(obj, name=name, help=entry.description or None)
            if parent is app:
                groups[name] = obj
        else:  # the CLI's one error path, whether or not the plugin decorated its command
            settings = getattr(obj, "context_settings", None)  # a broken command takes any option
            command = parent.command(name, help=entry.description or None, context_settings=settings)
            command(handle_errors()(obj))


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

    from physinfer.plugins import disabled_plugins

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
    err_console.print(f"[bold red]error:[/] {message}; see `physinfer --help`", highlight=False, soft_wrap=True)
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
