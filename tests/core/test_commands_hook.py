import typer

from physinfer import hookimpl
from physinfer.plugins import load_registry


def hello(name: str = "world") -> None:
    print(f"hello {name}")


def test_command_hook_registers_commands():
    class Commands:
        @hookimpl
        def physinfer_register_commands(self, registry):
            registry.add_command("hello", hello, "say hello")

    registry, _ = load_registry(extra_plugins={"cmds": Commands()})
    entry = registry.get("commands", "hello")
    assert entry.plugin == "cmds" and entry.load() is hello


def test_embedder_and_effect_hooks_via_registry():
    class Extra:
        @hookimpl
        def physinfer_register_embedders(self, registry):
            registry.add_embedder("copy_grid", "physinfer.embedders:GridSpectrumEmbedder")

        @hookimpl
        def physinfer_register_effects(self, registry):
            registry.add_effect("wobble", "pendulum_example.physics:QuadraticDrag", phenomenon="pendulum_lab")

        @hookimpl
        def physinfer_register_optimizers(self, registry):
            registry.add_optimizer("rnd2", "physinfer.optimizers.random:RandomOptimizer")

    registry, _ = load_registry(extra_plugins={"extra": Extra()})
    assert registry.embedder("copy_grid").n_frames > 0
    assert "wobble" in registry.effects_of("pendulum_lab")
    assert registry.optimizer("rnd2", dim=2).ask(1)[0].x.shape == (2,)


def test_subcommands_named_group_space_name_share_one_group(monkeypatch):
    """Two plugins contribute ``physinfer check a`` and ``physinfer check b``."""
    from typer.testing import CliRunner

    from physinfer.cli import app as cli

    def cmd_a() -> None:
        print("a ran")

    def cmd_b() -> None:
        print("b ran")

    class One:
        @hookimpl
        def physinfer_register_commands(self, registry):
            registry.add_command("check a", cmd_a, "first")

    class Two:
        @hookimpl
        def physinfer_register_commands(self, registry):
            registry.add_command("check b", cmd_b, "second")

    registry, infos = load_registry(extra_plugins={"one": One(), "two": Two()})
    app = typer.Typer()
    monkeypatch.setattr(cli, "app", app)
    monkeypatch.setattr(cli, "registry_and_infos", lambda: (registry, infos))
    cli._mount_plugin_commands()
    runner = CliRunner()
    assert "a ran" in runner.invoke(app, ["check", "a"]).output
    assert "b ran" in runner.invoke(app, ["check", "b"]).output
    help_text = runner.invoke(app, ["check", "--help"]).output
    assert "first" in help_text and "second" in help_text
