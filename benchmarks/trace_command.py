"""Which modules of physinfer a command passes through: the count behind docs/architecture.md's
"Following a command".

Runs one CLI command in this process under a profile hook (``sys.setprofile``) that records
the module of every physinfer function called, from the command on; for ``refine`` it stops
at the first trial's ``simulate`` (a θ the optimizer asked for) (the path from the CLI to the simulator), otherwise at the
command's end. Prints JSON: the modules in order of first call, and how many functions of
each were called. Concepts are counted from this list by hand (the rule is in the doc).

    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/trace_command.py -- \\
        refine --plugin pendulum_lab --out /tmp/trace_refine --overwrite
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from typing import Any

#: Modules a trace passes through that hold no concept of the path, and why (the counting rule
#: of docs/architecture.md); every other module of core on the path holds one. The CLI's own
#: modules (``physinfer.cli.*``) are counted apart.
NOT_CONCEPTS: dict[str, str] = {
    "physinfer": "the package face: its lazy __getattr__ hands out the API",
    "physinfer.settings": "setting converters (a kernel utility)",
    "physinfer.api.values": "option values checked and converted (a kernel utility)",
    "physinfer.api.plugins": "the registry loaded once for the API",
    "physinfer.plugins": "plugin loading (pluggy)",
    "physinfer.builtins": "the built-in plugin's registrations",
    "physinfer.scene": "the default scene's settings, read by the renderer",
    "physinfer.conditioning": "a user's video framing: an empty record on this path",
    "physinfer.threads": "thread limits (a kernel utility)",
    "physinfer.io": "atomic writes (a kernel utility)",
    "physinfer.outputs": "the --out folder's manifest (a kernel utility)",
    "physinfer.locking": "the run directory's lock (a kernel utility)",
    "physinfer.devices": "the torch device checked (a kernel utility)",
    "physinfer.progress": "progress bars (a kernel utility)",
    "physinfer.types": "the clip and trajectory arrays the roles pass (values, met with the roles)",
    "physinfer.embedders": "the built-in embedder: one plugin's Embedder",
    "physinfer.video": "frame operations inside the embedder",
    "physinfer.rendering": "the OpenGL helpers a plugin's Renderer draws with",
    "physinfer.render_replay": "the OpenGL helpers a plugin's Renderer draws with",
    "physinfer.posterior.infer_workflow": "asks whether an estimator applies (none: another path)",
    "physinfer.trial_workers": "asks for trial workers (--workers 0: none; another path)",
}


class _Reached(BaseException):
    """Raised from the hook when the path reaches the simulator (not an ``Exception``: the
    evaluation turns a simulator's exceptions into failed trials)."""


def _called_from_loop(frame: Any) -> bool:
    """Whether a trial of the loop is being evaluated (not the target's own simulation, nor
    the observation noise's re-simulations before the first trial)."""
    while frame is not None:
        if frame.f_code.co_name == "evaluate_batch" and frame.f_globals.get("__name__") == "physinfer.evaluation":
            return True
        frame = frame.f_back
    return False


def _importing(frame: Any) -> bool:
    """Whether this call runs while a physinfer module is being imported (a module body, a
    dataclass being made): an import, not a step of the command's path."""
    while frame is not None:
        if frame.f_code.co_name in ("<module>", "__create_fn__") and frame.f_globals.get(
            "__name__", ""
        ).startswith("physinfer"):
            return True
        frame = frame.f_back
    return False


def trace(command: list[str], until: str | None = None) -> dict[str, Any]:
    """Run ``physinfer COMMAND`` here under the hook; the modules it passed through.

    ``until``: stop at the first trial's call of a plugin function whose name starts so
    (``None``: ``"simulate"`` for refine, the command's end otherwise).
    """
    import typer

    from physinfer.cli.app import mounted_app

    until = until or ("simulate" if command[:1] == ["refine"] else None)
    order: list[str] = []
    calls: Counter[str] = Counter()
    functions: dict[str, set[str]] = {}

    def hook(frame: Any, event: str, _arg: Any) -> None:
        if event != "call":
            return
        module = frame.f_globals.get("__name__", "")
        if not module.startswith("physinfer") or module.startswith("physinfer_"):
            if until and frame.f_code.co_name.startswith(until) and _called_from_loop(frame):
                raise _Reached
            return
        if _importing(frame):
            return
        if module not in calls:
            order.append(module)
        calls[module] += 1
        functions.setdefault(module, set()).add(frame.f_code.co_name)

    cli = typer.main.get_command(mounted_app())  # plugin-registered commands (diagnose, infer) too
    reached = False
    sys.setprofile(hook)
    try:
        cli.main(command, standalone_mode=False)
    except _Reached:
        reached = True
    finally:
        sys.setprofile(None)
    return {
        "command": command,
        "until": until,
        "reached": reached,
        "modules": len(order),
        "concept_modules": [m for m in order if m not in NOT_CONCEPTS and not m.startswith("physinfer.cli")],
        "order": [{"module": m, "calls": calls[m], "functions": sorted(functions[m])} for m in order],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--until", default=None, help="stop at the first trial's call of a plugin function "
                        "whose name starts so (default: 'simulate' for refine, the command's end otherwise)")
    parser.add_argument("command", nargs=argparse.REMAINDER, help="the physinfer command, after --")
    args = parser.parse_args()
    print(json.dumps(trace([a for a in args.command if a != "--"], args.until), indent=1))


if __name__ == "__main__":
    main()
