"""A plugin cannot shadow a built-in or another plugin's name (issue 45, item 4).

A plugin command named like one of physinfer's own (``simulate``), or a phenomenon, optimizer,
embedder, effect or command another plugin registered first, is refused by name: the plugin
lists it under ``refused`` in ``physinfer plugins`` and the built-in keeps working. The host's
plugins (the ``physinfer`` distribution's: ``builtins``, ``flag``, ``hanging_cloth``) register
first, whatever a third party's entry-point name sorts as or its hooks' ``tryfirst``.
"""

import json
import os
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from physinfer import hookimpl
from physinfer.plugins import load_registry
from physinfer.registry import HOST_COMMANDS

BIN = Path(sys.executable).parent / "physinfer"


def shadow_simulate() -> None:
    print("the plugin's simulate ran")


def mine() -> None:
    print("mine ran")


class Shadowing:
    """Registers a built-in's name of every kind, and one name of its own."""

    @hookimpl(tryfirst=True)
    def physinfer_register_commands(self, registry):
        registry.add_command("simulate", shadow_simulate, "replaces the built-in")
        registry.add_command("refine extra", shadow_simulate, "under a built-in command")
        registry.add_command("diagnose", shadow_simulate, "a built-in plugin's command")
        registry.add_command("mine", mine, "its own")

    @hookimpl(tryfirst=True)
    def physinfer_register_optimizers(self, registry):
        registry.add_optimizer("ax", "physinfer.optimizers.random:RandomOptimizer")

    @hookimpl(tryfirst=True)
    def physinfer_register_phenomena(self, registry):
        registry.add_phenomenon("pendulum_lab", "x:y")

    @hookimpl(tryfirst=True)
    def physinfer_register_embedders(self, registry):
        registry.add_embedder("grid_spectrum", "x:y")

    @hookimpl(tryfirst=True)
    def physinfer_register_effects(self, registry):
        registry.add_effect("quadratic_drag", "x:y", phenomenon="pendulum_lab")


def test_a_plugin_cannot_take_a_builtin_name_of_any_kind():
    registry, infos = load_registry(extra_plugins={"shadow": Shadowing()})
    assert registry.entries["optimizers"]["ax"].plugin == "builtins"
    assert registry.entries["phenomena"]["pendulum_lab"].plugin == "pendulum_lab"
    assert registry.entries["embedders"]["grid_spectrum"].plugin == "builtins"
    assert registry.entries["effects"]["quadratic_drag"].plugin == "pendulum_lab"
    assert registry.entries["commands"]["diagnose"].plugin == "builtins"
    assert "simulate" not in registry.entries["commands"]
    assert "refine extra" not in registry.entries["commands"]
    assert registry.entries["commands"]["mine"].plugin == "shadow"  # the rest of it loads
    refused = " | ".join(infos["shadow"].refused)
    for what in (
        "command 'simulate'",
        "command 'refine extra'",
        "command 'diagnose'",
        "optimizer 'ax'",
        "phenomenon 'pendulum_lab'",
        "embedder 'grid_spectrum'",
        "effect 'quadratic_drag'",
    ):
        assert f"{what} refused" in refused, refused
    assert "physinfer's own command" in refused and "plugin 'builtins' registered it first" in refused
    assert infos["shadow"].error is None  # refused names, not a plugin that failed to load
    assert all(not info.refused for name, info in infos.items() if name != "shadow")


def test_of_two_plugins_the_first_keeps_the_name_and_the_second_is_refused():
    class One:
        @hookimpl
        def physinfer_register_commands(self, registry):
            registry.add_command("twice", mine, "first")

    class Two:
        @hookimpl(tryfirst=True)
        def physinfer_register_commands(self, registry):
            registry.add_command("twice", shadow_simulate, "second")

    registry, infos = load_registry(
        extra_plugins={"one": One(), "two": Two()}, load_entry_points=False
    )
    assert registry.entries["commands"]["twice"].plugin == "one"
    assert infos["two"].refused == [
        "command 'twice' refused: plugin 'one' registered it first (rename it in this plugin)"
    ]
    assert not infos["one"].refused


def test_an_entry_point_sorting_before_the_builtins_does_not_win(monkeypatch, tmp_path):
    (tmp_path / "aaa_shadow_plugin.py").write_text(
        "from physinfer import hookimpl\n\n"
        "@hookimpl\n"
        "def physinfer_register_optimizers(registry):\n"
        "    registry.add_optimizer('ax', 'physinfer.optimizers.random:RandomOptimizer')\n\n"
        "@hookimpl\n"
        "def physinfer_register_phenomena(registry):\n"
        "    registry.add_phenomenon('flag', 'x:y')\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    real = metadata.entry_points

    def with_shadow(**kwargs):
        eps = list(real(**kwargs))
        if kwargs.get("group") == "physinfer":
            eps.append(metadata.EntryPoint("aaa", "aaa_shadow_plugin", "physinfer"))
        return eps

    monkeypatch.setattr(metadata, "entry_points", with_shadow)
    registry, infos = load_registry()
    assert registry.entries["optimizers"]["ax"].plugin == "builtins"
    assert registry.entries["phenomena"]["flag"].plugin == "flag"
    assert len(infos["aaa"].refused) == 2


def test_a_subcommand_a_builtin_group_has_is_refused_when_mounted(monkeypatch):
    """``dataset generate`` is a command of the built-in ``dataset`` group, not a registered
    name; a plugin's ``dataset generate`` is refused when the CLI is mounted."""
    from physinfer.cli import app as cli

    class Sub:
        @hookimpl
        def physinfer_register_commands(self, registry):
            registry.add_command("dataset generate", shadow_simulate, "replaces a subcommand")
            registry.add_command("dataset mine", mine, "a new one")

    registry, infos = load_registry(extra_plugins={"sub": Sub()})
    app = typer.Typer()
    monkeypatch.setattr(cli, "app", app)
    monkeypatch.setattr(cli, "registry_and_infos", lambda: (registry, infos))
    cli._mount_plugin_commands()
    runner = CliRunner()
    assert "--preset" in runner.invoke(app, ["dataset", "generate", "--help"]).output
    assert "mine ran" in runner.invoke(app, ["dataset", "mine"]).output
    assert infos["sub"].refused == [
        "command 'dataset generate' refused: the group 'dataset' has that command already "
        "(rename it in this plugin)"
    ]


def test_the_host_commands_are_the_apps_own():
    from physinfer.cli import app as cli

    names = [info.name for info in cli.app.registered_commands]
    assert tuple(names[: len(HOST_COMMANDS)]) == HOST_COMMANDS


SHADOW_MODULE = '''
from physinfer import hookimpl


def simulate(as_json: bool = False) -> None:
    print("the plugin's simulate ran")


@hookimpl
def physinfer_register_commands(registry):
    registry.add_command("simulate", simulate, "replaces the built-in")
    registry.add_command("dataset generate", simulate, "replaces a built-in subcommand")
'''


@pytest.fixture(scope="module")
def shadow_distribution(tmp_path_factory):
    """A distribution ``shadowplug`` whose plugin ``aaa`` (sorting first) takes built-in names."""
    root = tmp_path_factory.mktemp("shadow")
    info = root / "shadowplug-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: shadowplug\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[physinfer]\naaa = shadow_plugin_module\n")
    (root / "shadow_plugin_module.py").write_text(SHADOW_MODULE)
    return root


def run_with(plugins: Path, *args: str) -> subprocess.CompletedProcess:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(plugins), os.environ.get("PYTHONPATH")])),
    }
    return subprocess.run([str(BIN), *args], capture_output=True, text=True, env=env, timeout=180)


def test_the_builtin_simulate_keeps_working_and_plugins_lists_the_refusal(shadow_distribution):
    proc = run_with(shadow_distribution, "simulate", "--help")
    assert proc.returncode == 0, proc.stderr
    assert "--trajectory-out" in proc.stdout and "plugin's simulate" not in proc.stdout
    proc = run_with(shadow_distribution, "dataset", "generate", "--help")
    assert proc.returncode == 0 and "--preset" in proc.stdout, proc.stderr

    proc = run_with(shadow_distribution, "plugins", "--json")
    assert proc.returncode == 0, proc.stderr
    row = {r["name"]: r for r in json.loads(proc.stdout)["plugins"]}["aaa"]
    assert row["error"] is None and row["commands"] == []
    assert row["refused"] == [
        "command 'simulate' refused: physinfer's own command has that name (rename it in this plugin)",
        "command 'dataset generate' refused: the group 'dataset' has that command already "
        "(rename it in this plugin)",
    ]
    listed = " ".join(proc.stderr.split())
    assert "plugin 'aaa': command 'simulate' refused" in listed
