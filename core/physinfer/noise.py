"""Where the noise floor was: a distance's noise floor is measured in
:mod:`physinfer.evaluation`, beside the distance itself (2026-11-30). Its old names are found
here with a warning (:data:`physinfer.moved.MOVED`).
"""

from __future__ import annotations

from physinfer.moved import moved_names

__getattr__ = moved_names(__name__)
