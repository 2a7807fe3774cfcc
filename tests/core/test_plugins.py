from importlib import metadata

import pytest

from physinfer import hookimpl
from physinfer.errors import UserInputError
from physinfer.plugins import get_plugin_manager, load_registry


def test_entry_points_load_builtins_and_example():
    registry, infos = load_registry()
    assert {"ax", "random", "cma"} <= set(registry.entries["optimizers"])
    assert "pendulum_lab" in registry.entries["phenomena"]
    assert registry.entries["effects"]["quadratic_drag"].extra["phenomenon"] == "pendulum_lab"
    assert infos["builtins"].distribution == "physinfer"
    assert all(info.error is None for info in infos.values())


def test_disabled_plugins_env(monkeypatch):
    monkeypatch.setenv("PHYSINFER_DISABLED_PLUGINS", "pendulum_lab, cma_missing")
    registry, infos = load_registry()
    assert "pendulum_lab" not in registry.entries["phenomena"]
    assert "pendulum_lab" not in infos


def test_broken_plugin_is_reported_and_others_load(monkeypatch):
    real = metadata.entry_points

    def with_broken(**kwargs):
        eps = list(real(**kwargs))
        if kwargs.get("group") == "physinfer":
            eps.append(metadata.EntryPoint("broken", "no_such_module_xyz.plugin", "physinfer"))
        return eps

    monkeypatch.setattr(metadata, "entry_points", with_broken)
    registry, infos = load_registry()
    assert infos["broken"].error.startswith("ModuleNotFoundError")
    assert "no_such_module_xyz" in infos["broken"].error
    assert "pendulum_lab" in registry.entries["phenomena"]


def test_plugin_whose_hook_raises_is_reported():
    class Bad:
        @hookimpl
        def physinfer_register_phenomena(self, registry):
            raise RuntimeError("boom")

    registry, infos = load_registry(extra_plugins={"bad": Bad()})
    assert "boom" in infos["bad"].error
    assert "pendulum_lab" in registry.entries["phenomena"]


def test_unknown_plugin_lists_installed():
    registry, _ = load_registry()
    with pytest.raises(UserInputError, match=r"unknown plugin/phenomenon 'nope'; installed: .*pendulum"):
        registry.phenomenon("nope")


def test_fresh_manager_each_call():
    pm1, _ = get_plugin_manager()
    pm2, _ = get_plugin_manager()
    assert pm1 is not pm2


def test_duplicate_registration_is_refused_by_name():
    class Dup:
        @hookimpl
        def physinfer_register_optimizers(self, registry):
            registry.add_optimizer("ax", "x:y")

    registry, infos = load_registry(extra_plugins={"dup": Dup()})
    assert infos["dup"].refused == [
        "optimizer 'ax' refused: plugin 'builtins' registered it first (rename it in this plugin)"
    ]
    assert registry.entries["optimizers"]["ax"].plugin == "builtins"
