"""pytest fixtures for plugin authors, published through the ``pytest11`` entry point.

- ``physinfer_registry``: a freshly loaded registry of all installed plugins.
- ``physinfer_run_dir``: an empty run directory under pytest's ``tmp_path``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from physinfer.plugins import load_registry


@pytest.fixture
def physinfer_registry():
    """A new registry (fresh plugin manager) per test."""
    registry, _infos = load_registry()
    return registry


@pytest.fixture
def physinfer_run_dir(tmp_path: Path) -> Path:
    """A path for ``--out`` that does not exist yet."""
    return tmp_path / "run"
