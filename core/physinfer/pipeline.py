"""Where a pipeline's builders were: they live in :mod:`physinfer.evaluation`, beside the
:class:`~physinfer.evaluation.Pipeline` they build and evaluate (2026-11-30). Their old names
are found here with a warning (:data:`physinfer.moved.MOVED`).
"""

from __future__ import annotations

from physinfer.moved import moved_names

__getattr__ = moved_names(__name__)
