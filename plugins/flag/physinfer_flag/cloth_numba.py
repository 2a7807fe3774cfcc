"""Where numba keeps the compiled cloth kernels, decided before any kernel is defined.

The kernels are compiled with ``cache=True`` so that only the first run on a machine pays
the few seconds of compilation. Numba writes its cache next to the module (``__pycache__``)
or, when that is read-only (an installed wheel), in the user's cache directory; if neither
is writable, defining a cached function fails at import. :func:`ensure_cache_dir` points
numba at a writable temporary directory in that case, unless ``NUMBA_CACHE_DIR`` already
names one. Import this module before defining ``@njit(cache=True)`` functions.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numba


def _writable(path: Path) -> bool:
    """True if ``path`` exists and is writable, or can be created."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(path, os.W_OK)


def ensure_cache_dir() -> str | None:
    """Give numba a writable cache directory when its defaults are not writable.

    Returns:
        The directory set, or ``None`` when numba's own choice (or ``NUMBA_CACHE_DIR``) stands.
    """
    if numba.config.CACHE_DIR:
        return None
    if _writable(Path(__file__).parent / "__pycache__"):
        return None
    user_cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "numba"
    if _writable(user_cache):
        return None
    fallback = Path(tempfile.gettempdir()) / "physinfer-numba-cache"
    if not _writable(fallback):
        return None
    numba.config.CACHE_DIR = str(fallback)
    return str(fallback)


ensure_cache_dir()
