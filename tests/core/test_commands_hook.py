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
            registry.add_effect("wobble", "pendulum_example.physics:QuadraticDrag", phenomenon="pendulum")

        @hookimpl
        def physinfer_register_optimizers(self, registry):
            registry.add_optimizer("rnd2", "physinfer.optimizers.random:RandomOptimizer")

    registry, _ = load_registry(extra_plugins={"extra": Extra()})
    assert registry.embedder("copy_grid").n_frames > 0
    assert "wobble" in registry.effects_of("pendulum")
    assert registry.optimizer("rnd2", dim=2).ask(1)[0].x.shape == (2,)
    assert isinstance(typer.Typer(), typer.Typer)
