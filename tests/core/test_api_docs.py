"""The API reference: ``make docs`` builds it with pdoc, and every public name has a docstring.

The documented modules are the Makefile's ``API_MODULES`` (one list, read here). Public
names are a module's ``__all__``, or else the classes and functions it defines whose names
do not start with ``_``; for a class, also the methods and properties it defines itself.
"""

from __future__ import annotations

import importlib
import inspect
import re
import subprocess
import sys
import types
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def api_modules() -> list[str]:
    """The module arguments of ``make docs`` (``API_MODULES`` in the Makefile)."""
    text = (ROOT / "Makefile").read_text().replace("\\\n", " ")
    match = re.search(r"^API_MODULES\s*:?=\s*(.+)$", text, re.MULTILINE)
    assert match, "the Makefile defines API_MODULES for `make docs`"
    return [arg.strip("'\"") for arg in match.group(1).split()]  # as the shell passes them


def documented_modules() -> list[str]:
    """The importable modules among ``API_MODULES`` (without pdoc's ``!`` exclusions)."""
    return [m for m in api_modules() if not m.startswith("!")]


def _members(module: types.ModuleType) -> dict[str, object]:
    names = getattr(module, "__all__", None)
    if names is not None:
        return {name: getattr(module, name) for name in names}
    return {
        name: obj
        for name, obj in vars(module).items()
        if not name.startswith("_")
        and (inspect.isclass(obj) or inspect.isfunction(obj))
        and getattr(obj, "__module__", None) == module.__name__
    }


def _has_doc(obj: object) -> bool:
    doc = obj.__doc__ if not isinstance(obj, property) else (obj.fget.__doc__ if obj.fget else None)
    return bool(doc and doc.strip())


def undocumented(module: types.ModuleType) -> list[str]:
    """Public names of ``module`` (and public methods of its public classes) without a docstring."""
    missing = [] if _has_doc(module) else [module.__name__]
    for name, obj in _members(module).items():
        if not (inspect.isclass(obj) or callable(obj)):
            continue  # constants are described in the module's docstring
        if not _has_doc(obj):
            missing.append(f"{module.__name__}.{name}")
        if inspect.isclass(obj) and obj.__module__.startswith("physinfer"):
            for attr, member in vars(obj).items():
                if attr.startswith("_"):
                    continue
                if isinstance(member, (staticmethod, classmethod)):
                    member = member.__func__
                if (inspect.isfunction(member) or isinstance(member, property)) and not _has_doc(
                    member
                ):
                    missing.append(f"{module.__name__}.{name}.{attr}")
    return missing


def test_every_public_name_of_the_api_reference_has_a_docstring():
    missing = []
    for name in documented_modules():
        missing += undocumented(importlib.import_module(name))
    assert missing == [], f"public names without a docstring: {', '.join(missing)}"


def test_the_check_finds_an_undocumented_name():
    module = types.ModuleType("physinfer_fake", "A module.")

    def documented() -> None:
        """Documented."""

    def bare() -> None:
        pass

    class Thing:
        """A class."""

        def method(self) -> None:
            pass

    for obj in (documented, bare, Thing):
        obj.__module__ = "physinfer_fake"
        setattr(module, obj.__name__, obj)
    assert undocumented(module) == ["physinfer_fake.bare", "physinfer_fake.Thing.method"]
    module.__all__ = ["documented"]
    assert undocumented(module) == []


def test_make_docs_builds_the_reference_with_pdoc(tmp_path):
    """The command ``make docs`` runs, into a temporary folder; pdoc must not warn."""
    pytest.importorskip("pdoc", reason="pdoc is a dev extra: pip install -e '.[dev]'")
    out = tmp_path / "api"
    proc = subprocess.run(
        [sys.executable, "-m", "pdoc", "-d", "google", "-o", str(out), *api_modules()],
        capture_output=True, text=True, timeout=300, cwd=ROOT,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "warn" not in proc.stderr.lower(), proc.stderr[-3000:]
    for name in documented_modules():
        page = out / (name.replace(".", "/") + ".html")
        assert page.is_file(), f"no page for {name}"
    roles = (out / "physinfer" / "roles.html").read_text()
    assert (
        'id="Effect.term"' in roles
        and 'id="ParameterSpace.merged"' in (out / "physinfer" / "parameters.html").read_text()
    )
    assert (out / "index.html").is_file()
