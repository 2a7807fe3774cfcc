"""Names that moved (:mod:`physinfer.moved`): every old path still finds its object, with a
DeprecationWarning naming the new one, and nothing in the repository uses an old path.

A module that only re-exported what moved out of it hid where things live (14 of 17 imports
of ``Pipeline`` named ``physinfer.loop``; issue 47). The old modules now answer those names
through one map, and code here imports each name from the module that defines it.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import inspect
import pickle
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path

import pytest

from physinfer.moved import MOVED, moved_names, resolve

ROOT = Path(__file__).resolve().parents[2]
#: Where the repository's own code lives: all of it imports names from where they are defined.
SCANNED = ("core", "plugins", "examples", "tests", "benchmarks")


def _all_moved() -> dict[str, str]:
    """The core map and each plugin's (the flag's old renderer module keeps its own)."""
    flag_render = importlib.import_module("physinfer_flag.render")
    return {**MOVED, **flag_render.MOVED}


def _old_module(path: str) -> str:
    return path.rpartition(".")[0]


@pytest.mark.parametrize("old", sorted(_all_moved()))
def test_an_old_path_warns_and_gives_the_same_object(old: str):
    new = _all_moved()[old]
    module, _, name = old.rpartition(".")
    with pytest.warns(DeprecationWarning, match=f"{old} moved to {new}"):
        found = getattr(importlib.import_module(module), name)
    assert found is resolve(new)
    if inspect.isclass(found) or inspect.isfunction(found):
        assert found.__module__ == _old_module(new), f"{new} is not where {name} is defined"
    else:  # a constant: the new module assigns it
        assert name in defined_names(Path(importlib.util.find_spec(_old_module(new)).origin))  # type: ignore[arg-type]


def test_an_import_from_the_old_path_and_a_pickle_naming_it_still_load():
    names: dict[str, object] = {}
    with pytest.warns(DeprecationWarning, match="physinfer.loop.Pipeline moved"):
        exec("from physinfer.loop import Pipeline", names)  # the old line, unseen by the scan below
    assert names["Pipeline"] is resolve("physinfer.evaluation.Pipeline")
    with pytest.warns(DeprecationWarning):  # a job pickled before the move names the old module
        assert pickle.loads(b"cphysinfer.datasets.engine\nGenerateProgress\n.") is resolve(
            "physinfer.datasets.resume.GenerateProgress"
        )


def test_a_name_that_never_was_there_is_still_an_attribute_error():
    import physinfer.loop

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(AttributeError, match="has no attribute 'Pipelin'"):
            _ = physinfer.loop.Pipelin
        assert physinfer.loop.run_refinement.__module__ == "physinfer.loop"  # its own: no warning


def defined_names(path: Path) -> set[str]:
    """The names a module's top level defines (functions, classes, assignments)."""
    names: set[str] = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return names


def borrowed_imports(files: Iterable[Path], defined: Mapping[str, set[str]], root: Path) -> list[str]:
    """``file:line module.name`` of every import of a name from one of ``defined``'s modules
    that the module does not define itself (a moved name, or one it only imports)."""
    found = []
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module in defined:
                found += [
                    f"{path.relative_to(root).as_posix()}:{node.lineno} {node.module}.{alias.name}"
                    for alias in node.names
                    if alias.name not in defined[node.module]
                ]
    return found


def _python_files() -> list[Path]:
    return [p for top in SCANNED for p in sorted((ROOT / top).rglob("*.py")) if ".venv" not in p.parts]


def test_no_code_here_imports_a_name_from_a_module_that_does_not_define_it():
    old_modules = {_old_module(old) for old in _all_moved()}
    defined = {m: defined_names(Path(importlib.util.find_spec(m).origin)) for m in old_modules}  # type: ignore[arg-type]
    assert borrowed_imports(_python_files(), defined, ROOT) == [], (
        "import these from the module that defines them (physinfer.moved.MOVED names it)"
    )


def test_the_checks_can_fail(tmp_path: Path):
    (tmp_path / "user.py").write_text(
        "from old import Moved, own\n"
        "def f():\n"
        "    from old import Imported\n"
        "    from new import Moved\n"
    )
    assert borrowed_imports([tmp_path / "user.py"], {"old": {"own"}}, tmp_path) == [
        "user.py:1 old.Moved", "user.py:3 old.Imported"
    ]
    getattr_ = moved_names("old", {"old.Moved": "physinfer.evaluation.Pipeline"})
    with pytest.warns(DeprecationWarning, match="import it from physinfer.evaluation"):
        assert getattr_("Moved") is resolve("physinfer.evaluation.Pipeline")
    with pytest.raises(AttributeError, match="module 'old' has no attribute 'own'"):
        getattr_("own")
