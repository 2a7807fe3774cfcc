"""Where the loop's re-simulations were: the observation noise, the selection of the best fit
and the noise floor at it are parts of a refinement run and live in :mod:`physinfer.loop`
(2026-11-29). Their old names are found here with a warning (:data:`physinfer.moved.MOVED`).
"""

from __future__ import annotations

from physinfer.moved import moved_names

__getattr__ = moved_names(__name__)
