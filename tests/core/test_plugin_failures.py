"""A broken plugin stays the plugin's problem (issue 25, item 5).

Each test installs broken plugins the way a user would have them: a distribution with an
``entry_points.txt`` on ``sys.path`` (a ``*.dist-info`` folder in a temporary directory put on
``PYTHONPATH``), and runs the real ``physinfer`` console script in a subprocess.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from physinfer.errors import PhysinferError
from physinfer.plugins import check_references, load_registry

BIN = Path(sys.executable).parent / "physinfer"

MODULES = {
    # A hook name physinfer has no specification for: pluggy's check_pending raised for it.
    "fake_misspelled": """
from physinfer import hookimpl

@hookimpl
def physinfer_register_phenomenom(registry):
    registry.add_phenomenon("never", "fake_misspelled:nothing")
""",
    "fake_raising": """
from physinfer import hookimpl

@hookimpl
def physinfer_register_optimizers(registry):
    raise RuntimeError("boom in the hook")
""",
    # Registers fine; its implementation module has a broken import, found only when used.
    "fake_lazy": """
from physinfer import hookimpl

@hookimpl
def physinfer_register_phenomena(registry):
    registry.add_phenomenon("lazyphen", "fake_lazy_impl:make", "imports a missing module")

@hookimpl
def physinfer_register_commands(registry):
    registry.add_command("lazycmd", "fake_lazy_impl:command", "a command of a broken module")
""",
    "fake_lazy_impl": "import no_such_module_for_physinfer_tests  # noqa\n",
}


@pytest.fixture(scope="module")
def broken_plugins(tmp_path_factory):
    """A folder holding the ``fakeplug`` distribution and its three broken plugins."""
    root = tmp_path_factory.mktemp("plugins")
    info = root / "fakeplug-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: fakeplug\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[physinfer]\nmisspelled = fake_misspelled\nraising = fake_raising\nlazy = fake_lazy\n"
    )
    for name, text in MODULES.items():
        (root / f"{name}.py").write_text(text)
    return root


def run_with(plugins: Path, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(plugins), os.environ.get("PYTHONPATH")])),
    }
    return subprocess.run(
        [str(BIN), *args], capture_output=True, text=True, env=env, cwd=cwd, timeout=180
    )


def test_help_and_plugins_list_every_broken_plugin_by_name_with_its_error(broken_plugins):
    help_ = run_with(broken_plugins, "--help")
    assert help_.returncode == 0, help_.stderr
    assert "refine" in help_.stdout and "Traceback" not in help_.stderr

    proc = run_with(broken_plugins, "plugins", "--json")
    assert proc.returncode == 0, proc.stderr
    rows = {row["name"]: row for row in json.loads(proc.stdout)["plugins"]}
    misspelled = rows["misspelled"]["error"]
    assert "unknown hook 'physinfer_register_phenomenom'" in misspelled
    assert "did you mean 'physinfer_register_phenomena'" in misspelled
    assert "boom in the hook" in rows["raising"]["error"]
    assert rows["lazy"]["error"] is None  # it registered; what it named does not import
    assert "no_such_module_for_physinfer_tests" in rows["lazy"]["unresolved"]["phenomenon lazyphen"]
    assert "command lazycmd" in rows["lazy"]["unresolved"]
    # Every other plugin still loads, and its names resolve.
    assert rows["pendulum_lab"]["phenomena"] == ["pendulum_lab"] and rows["pendulum_lab"]["error"] is None
    assert not rows["pendulum_lab"]["unresolved"] and not rows["builtins"]["unresolved"]

    # In full on stderr, one plugin a line (the table's cells are cut to the terminal's width).
    assert "Traceback" not in proc.stderr
    listed = " ".join(proc.stderr.split())
    assert "plugin 'lazy': phenomenon lazyphen: ModuleNotFoundError" in listed
    assert "plugin 'raising': RuntimeError in physinfer_register_optimizers: boom" in listed


def test_the_command_needing_a_broken_plugin_says_so_in_one_line(broken_plugins, tmp_path):
    for args in (
        ("simulate", "--plugin", "lazyphen", "--out", str(tmp_path / "x.mp4"), "--json"),
        ("lazycmd", "--json", "--any-option"),
    ):
        proc = run_with(broken_plugins, *args, cwd=tmp_path)
        assert proc.returncode == 2, proc.stderr
        line = " ".join(proc.stderr.split())  # one message (rich wraps it at the terminal's width)
        assert "Traceback" not in proc.stderr and line.count("error:") == 1
        assert line.startswith("error: plugin 'lazy' is broken") and "ModuleNotFoundError" in line
        assert "PHYSINFER_DISABLED_PLUGINS=lazy" in line
        assert json.loads(proc.stdout)["error"].startswith("plugin 'lazy' is broken")
    assert not (tmp_path / "x.mp4").exists()


def test_a_misspelled_hook_unregisters_only_its_plugin():
    from physinfer import hookimpl

    class Misspelled:
        @hookimpl
        def physinfer_register_optimizerz(self, registry):
            registry.add_optimizer("never", "x:y")

        @hookimpl
        def physinfer_register_phenomena(self, registry):
            registry.add_phenomenon("half", "x:y")

    registry, infos = load_registry(extra_plugins={"misspelled": Misspelled()})
    assert "unknown hook 'physinfer_register_optimizerz'" in infos["misspelled"].error
    assert "half" not in registry.entries["phenomena"]  # a plugin that fails to load is out whole
    assert "pendulum_lab" in registry.entries["phenomena"]


def test_an_unresolvable_name_fails_as_a_plugin_error_and_is_listed():
    from physinfer import hookimpl

    class Lazy:
        @hookimpl
        def physinfer_register_embedders(self, registry):
            registry.add_embedder("ghost", "physinfer.embedders:NoSuchEmbedder")

    registry, infos = load_registry(extra_plugins={"lazy": Lazy()}, load_entry_points=False)
    with pytest.raises(
        PhysinferError, match=r"plugin 'lazy' is broken: its embedder 'ghost'.*AttributeError"
    ):
        registry.embedder("ghost")
    check_references(registry, infos)
    assert infos["lazy"].unresolved["embedder ghost"].startswith("AttributeError")
