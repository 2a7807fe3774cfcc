"""The registry every API function builds its pipelines from, loaded once per process."""

from __future__ import annotations

import functools

from physinfer.plugins import load_registry
from physinfer.registry import Registry


@functools.cache
def registry() -> Registry:
    """The registry of every installed plugin, loaded once per process."""
    return load_registry()[0]
