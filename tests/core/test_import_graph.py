"""The layering of ``core/physinfer``: every module sits on one floor of the layer table
(``docs/architecture.md``) and imports only its own floor and those below; no two modules
import each other, directly or round a circle; the posterior and the diagnosis never import
each other; no module outside the CLI imports the CLI.

Every import counts: those inside functions (a lazy import that dodges a circle at start-up
is still a circle in the design) and those under ``if TYPE_CHECKING:`` (a type is a
dependency: a record defined above the code that uses it is a record in the wrong place).
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "core" / "physinfer"
PLUGINS = PACKAGE.parents[1] / "plugins"


def module_name(path: Path, package: Path = PACKAGE) -> str:
    parts = list(path.relative_to(package.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules_of(package: Path) -> dict[str, Path]:
    """Dotted name → file, for every module of ``package``."""
    return {module_name(p, package): p for p in package.rglob("*.py")}


MODULES = modules_of(PACKAGE)

#: The floors, bottom first; a module may import its own floor and those below. The posterior
#: and the diagnosis share a floor and never import each other.
FLOORS: dict[str, int] = {
    "kernel": 0,
    "plugins": 1,
    "engine": 2,
    "execution": 3,
    "footage": 4,  # and datasets
    "posterior": 5,
    "diagnosis": 5,
    "report": 6,
    "commands": 7,
    "api": 8,
    "cli": 9,
}

#: Every module of ``core/physinfer`` on its floor (modules keep their paths: plugins and
#: users import them). Where a module's place differs from its package's, or DESIGN.md's
#: list does not name it, the reason is beside it: its floor follows what it does.
TABLE: dict[str, dict[str, str]] = {
    "kernel": {
        "physinfer.errors": "",
        "physinfer.types": "",
        "physinfer.parameters": "",
        "physinfer.scene": "",
        "physinfer.roles": "",
        "physinfer.settings": "",
        "physinfer.io": "",
        "physinfer.locking": "",
        "physinfer.outputs": "the --out manifest every command claims its folder with, beside locking",
        "physinfer.console": "the stderr console; no physinfer import",
        "physinfer.moved": "old path -> new path of names that moved, for the old modules' "
        "__getattr__; no physinfer import",
        "physinfer.progress": "progress bars on that console, handed in by the callers above",
        "physinfer.devices": "a torch device checked before any work",
        "physinfer.registry": "the record plugins fill (scene and roles read it); the machinery "
        "that fills it (hooks, discovery) is the plugins floor",
        "physinfer.zeroed_heap": "glibc's heap zero-filled while the encoder runs (video's)",
        "physinfer.video": "clip arrays to and from files, and the frame operations (gray, crop, "
        "resample) every floor uses; conditioning a user's video is the footage floor's",
    },
    "plugins": {
        "physinfer.hooks": "",
        "physinfer.plugins": "",
        "physinfer.builtins": "",
        "physinfer.embedders": "the built-in plugin's embedders",
        "physinfer.tracking": "the built-in motion embedder's tracker (conditioning reuses it)",
        "physinfer.optimizers": "the built-in plugin's optimizers",
        "physinfer.optimizers.ax": "",
        "physinfer.optimizers.cma": "",
        "physinfer.optimizers.random": "",
        "physinfer.rendering": "what plugins' renderers are built from (headless pyrender)",
        "physinfer.render_replay": "",
        "physinfer.testing": "the contract kit plugin authors test against",
        "physinfer.testing.effects": "",
        "physinfer.testing.fixtures": "",
        "physinfer.testing.footage": "",
        "physinfer.testing.sensitivity": "",
    },
    "engine": {
        "physinfer.fixed": "the model spec's --fix",
        "physinfer.evaluation": "one model's pipeline: built, evaluated, its noise floor",
        "physinfer.pipeline": "old names of the pipeline's builders (physinfer.moved)",
        "physinfer.noise": "old names of the noise floor (physinfer.moved)",
        "physinfer.refinement": "the loop's typed records: SearchSpec, RefineResult",
        "physinfer.resimulation": "old names of the loop's re-simulations (physinfer.moved)",
        "physinfer.loop": "",
        "physinfer.rundir": "",
        "physinfer.plotting": "a run's own figure, drawn from its trial records",
        "physinfer.threads": "the torch thread limit the loop runs under",
        "physinfer.discrepancy.model": "the model file: diagnose writes it, refine reads it",
        "physinfer.discrepancy.warmstart": "an optimizer started at a point: refine and diagnose",
        "physinfer.posterior.fingerprint": "an embedder's identity (its embedding of a probe "
        "clip): the camera estimate and the posterior's estimator both check it",
    },
    "execution": {
        "physinfer.datasets.executors": "the executors (inline, processes, Dask) and how their "
        "worker processes start; every workflow's jobs run on them",
        "physinfer.trial_workers": "",
        "physinfer.worker_cache": "the models a worker thread builds once, for every workflow's jobs",
    },
    "footage": {
        "physinfer.conditioning": "",
        "physinfer.facing": "which way round a video shows its subject; mirrored to the renderer's",
        "physinfer.framing": "",
        "physinfer.framing.checks": "",
        "physinfer.framing.clip": "",
        "physinfer.framing.frames": "",
        "physinfer.framing.overlay": "",
        "physinfer.framing.region": "",
        "physinfer.framing.settings": "",
        "physinfer.framing.shake": "",
        "physinfer.static_background": "",
        "physinfer.render_estimate": "the camera estimate",
        "physinfer.meshio": "another simulator's meshes in",
        "physinfer.target": "the target: a user's video read and conditioned, or the phenomenon's",
        "physinfer.specs": "old names of the refine command's request (physinfer.moved)",
        "physinfer.as_given": "",
        "physinfer.adequacy": "a fit judged against what a camera does to a clip (as_given)",
        "physinfer.datasets": "",
        "physinfer.datasets.engine": "",
        "physinfer.datasets.generator": "",
        "physinfer.datasets.loader": "",
        "physinfer.datasets.plan": "",
        "physinfer.datasets.presets": "",
        "physinfer.datasets.resume": "",
        "physinfer.datasets.storage": "",
        "physinfer.datasets.worker": "",
    },
    "posterior": {
        "physinfer.posterior": "",
        "physinfer.posterior.calibrate_workflow": "",
        "physinfer.posterior.calibration": "",
        "physinfer.posterior.estimator": "",
        "physinfer.posterior.flows": "",
        "physinfer.posterior.features": "",
        "physinfer.posterior.figures": "",
        "physinfer.posterior.held_out": "",
        "physinfer.posterior.inputs": "",
        "physinfer.posterior.loading": "",
        "physinfer.posterior.refined": "",
        "physinfer.posterior.summary": "",
        "physinfer.posterior.train_workflow": "",
        "physinfer.posterior.training": "",
    },
    "diagnosis": {
        "physinfer.discrepancy.calibration_stage": "old names of the self-consistency stage (physinfer.moved)",
        "physinfer.discrepancy.candidates": "",
        "physinfer.discrepancy.clip_jobs": "",
        "physinfer.discrepancy.decide": "",
        "physinfer.discrepancy.figures": "",
        "physinfer.discrepancy.gap": "",
        "physinfer.discrepancy.ladder": "",
        "physinfer.discrepancy.limit_check": "",
        "physinfer.discrepancy.limit_rule": "",
        "physinfer.discrepancy.limit_stage": "",
        "physinfer.discrepancy.limit_text": "",
        "physinfer.discrepancy.limits": "",
        "physinfer.discrepancy.localise": "",
        "physinfer.discrepancy.needed_calibration": "old names of the self-consistency runs' choice "
        "(physinfer.moved)",
        "physinfer.discrepancy.self_consistency": "",
        "physinfer.discrepancy.parallel": "",
        "physinfer.discrepancy.progress": "",
        "physinfer.discrepancy.records": "",
        "physinfer.discrepancy.refit": "",
        "physinfer.discrepancy.reveal": "",
        "physinfer.discrepancy.ridge": "",
        "physinfer.discrepancy.screen": "",
        "physinfer.discrepancy.settings": "",
        "physinfer.discrepancy.stages": "",
        "physinfer.discrepancy.starts": "",
        "physinfer.discrepancy.verdict": "",
    },
    "report": {
        "physinfer.report": "",
        "physinfer.report.common": "",
        "physinfer.report.diagnose_page": "",
        "physinfer.report.infer_page": "",
        "physinfer.report.markup": "",
        "physinfer.report.page": "",
        "physinfer.report.refine_page": "",
    },
    "commands": {
        "physinfer.session": "the refine command and what it is asked (the request's specs)",
        "physinfer.discrepancy.workflow": "the diagnose command: runs the stages, writes the "
        "results, asks the report for its page",
        "physinfer.discrepancy.outputs": "the diagnose command's result files",
        "physinfer.discrepancy": "the package's face: run_diagnosis",
        "physinfer.posterior.infer_workflow": "the infer command: writes posterior.json and "
        "asks the report for its page",
        "physinfer.posterior.workflow": "the posterior commands' face (train, infer, calibrate)",
    },
    "api": {
        "physinfer": "the package's face: the api re-exported",
        "physinfer.api": "",
        "physinfer.api.footage": "",
        "physinfer.api.options": "",
        "physinfer.api.values": "",
        "physinfer.api.plugins": "",
        "physinfer.api.results": "",
    },
    "cli": {
        "physinfer.cli": "",
        "physinfer.cli.app": "",
        "physinfer.cli.common": "",
        "physinfer.cli.dataset_cmd": "",
        "physinfer.cli.diagnose_cmd": "",
        "physinfer.cli.options": "",
        "physinfer.cli.plugins_cmd": "",
        "physinfer.cli.posterior_cmd": "",
        "physinfer.cli.prepare_cmd": "",
        "physinfer.cli.refine_cmd": "",
        "physinfer.cli.render_cmd": "",
        "physinfer.cli.report_cmd": "",
        "physinfer.cli.simulate_cmd": "",
    },
}

LAYER = {module: layer for layer, modules in TABLE.items() for module in modules}


def imported(path: Path, modules: dict[str, Path] = MODULES) -> set[str]:
    """The ``modules`` ``path`` imports anywhere, type-only imports included
    (``from m import name`` counts as ``m.name`` when that is a module, else ``m``)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            subs = {f"{node.module}.{alias.name}" for alias in node.names}
            found.update(subs & modules.keys() or {node.module})
    return {name for name in found if name in modules}


def graph(modules: dict[str, Path] = MODULES) -> dict[str, set[str]]:
    """Module → the modules it imports (a package's own ``__init__`` excluded: importing a
    submodule runs its package first, which is no dependency of design)."""
    return {
        name: {t for t in imported(path, modules) if t != name and not name.startswith(t + ".")}
        for name, path in modules.items()
    }


def circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in edges.get(v, ()):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            connect(v)
    return found


def upward(edges: dict[str, set[str]], layer: dict[str, str]) -> list[str]:
    """``a (floor) -> b (floor)`` for every import of a module on a higher floor, or across
    the posterior/diagnosis wall."""
    found = []
    for a in sorted(edges):
        for b in sorted(edges[a]):
            la, lb = layer[a], layer[b]
            if FLOORS[lb] > FLOORS[la] or (FLOORS[lb] == FLOORS[la] and la != lb):
                found.append(f"{a} ({la}) -> {b} ({lb})")
    return found


def test_every_module_is_on_one_floor():
    listed = [module for modules in TABLE.values() for module in modules]
    assert len(listed) == len(set(listed)), "a module is listed on two floors"
    assert set(TABLE) == set(FLOORS)
    assert sorted(MODULES.keys() - LAYER.keys()) == [], "new modules: add them to TABLE"
    assert sorted(LAYER.keys() - MODULES.keys()) == [], "modules gone: drop them from TABLE"


def test_no_module_imports_a_higher_floor():
    assert upward(graph(), LAYER) == []


def test_posterior_and_diagnosis_never_import_each_other():
    # By package too: a module of one moved to another floor still keeps out of the other.
    walls = ("physinfer.posterior", "physinfer.discrepancy")
    crossings = [
        f"{a} -> {b}"
        for a, targets in graph().items()
        for b in targets
        for mine, other in (walls, walls[::-1])
        if a.startswith(mine) and b.startswith(other)
    ]
    assert crossings == []


def test_no_module_outside_the_cli_imports_the_cli():
    offenders = {
        name: sorted(t for t in targets if t.startswith("physinfer.cli"))
        for name, targets in graph().items()
        if not name.startswith("physinfer.cli")
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_no_import_circles():
    assert circles(graph()) == []


def test_the_shipped_plugins_have_no_import_circles():
    packages = sorted(p for p in PLUGINS.glob("*/physinfer_*") if p.is_dir())
    assert packages, f"no plugin packages under {PLUGINS}"
    assert {p.name: circles(graph(modules_of(p))) for p in packages} == {p.name: [] for p in packages}


def test_the_checks_can_fail(tmp_path: Path):
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert "physinfer.loop" in imported(MODULES["physinfer.session"])
    layer = {"k": "kernel", "e": "engine", "p": "posterior", "d": "diagnosis"}
    assert upward({"k": {"e"}, "e": {"k"}, "p": {"d", "e"}, "d": set()}, layer) == [
        "k (kernel) -> e (engine)",
        "p (posterior) -> d (diagnosis)",
    ]
    typed = tmp_path / "typed.py"
    typed.write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from physinfer.loop import Pipeline\n"
        "def f():\n    from physinfer.session import refine\n"
    )
    assert imported(typed) == {"physinfer.loop", "physinfer.session"}
