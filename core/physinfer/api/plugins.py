"""The registry every API function builds its pipelines from, loaded once per process."""

from __future__ import annotations

import functools
from typing import Any

from physinfer.plugins import load_registry


@functools.cache
def registry() -> Any:
    """The registry of every installed plugin, loaded once per process."""
    return load_registry()[0]
