"""Where a refinement's request was: :class:`~physinfer.session.RefineRequest` and its specs
(``ModelSpec``, ``TargetSpec``, ``ExecutionSpec``) live in :mod:`physinfer.session`, with the
refine command that is their only reader (2026-11-30). Their old names are found here with a
warning (:data:`physinfer.moved.MOVED`).
"""

from __future__ import annotations

from physinfer.moved import moved_names

__getattr__ = moved_names(__name__)
