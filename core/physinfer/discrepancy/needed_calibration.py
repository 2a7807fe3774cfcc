"""Where the choice of the self-consistency runs a diagnosis needs was: it lives in
:mod:`physinfer.discrepancy.self_consistency` (2026-11-30: one module for diagnose's
self-consistency runs, whose name is not the posterior's "calibration"). Its old names are
found here with a warning (:data:`physinfer.moved.MOVED`).
"""

from __future__ import annotations

from physinfer.moved import moved_names

__getattr__ = moved_names(__name__)
