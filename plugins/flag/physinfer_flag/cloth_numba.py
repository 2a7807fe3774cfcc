"""Where numba keeps the compiled cloth kernels, decided before any kernel is defined.

The kernels are compiled with ``cache=True`` so that only the first run on a machine pays
the few seconds of compilation. Numba writes its cache next to the module (``__pycache__``)
or, when that is read-only (an installed wheel), in the user's cache directory; if neither
is writable, defining a cached function fails at import. :func:`ensure_cache_dir` points
numba at a writable temporary directory in that case, unless ``NUMBA_CACHE_DIR`` already
names one. Import this module before defining ``@njit(cache=True)`` functions.

It also holds :data:`FASTMATH`, the fast-math flags every cloth kernel is compiled with,
and :func:`cache_depends_on`, which makes a kernel's cache go stale when a file it calls
into changes (numba checks only the kernel's own file).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable
from pathlib import Path
from types import ModuleType
from typing import Any

import numba

FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}
"""Fast math minus "nnan"/"ninf" (NaN tests must survive optimisation), for every kernel.

A kernel called from another inherits the caller's flags only when it is compiled for
that call; numba's cache does not key on flags, so a helper first compiled alone (a test
calling it from Python) would be reused by its callers with other flags and round
differently. Helpers therefore state these flags themselves, and the bits of a
simulation do not depend on which function a process happened to compile first.
"""


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


def cache_depends_on(dispatchers: Iterable[Any], *modules: ModuleType) -> None:
    """Let the cached code of ``dispatchers`` go stale when any of ``modules`` changes.

    Numba links a kernel's callees into the kernel's cached code but checks only the
    kernel's own source file: after an edit of a force kernel in ``cloth_forces.py``,
    ``run_flag`` (in ``cloth_kernels.py``) would keep running the old forces from its
    cache. Adding the other files' stamps (modification time, size) to the stamp the
    cache index is checked against recompiles the kernel when any of them changes. This
    reaches into numba's cache object; where it is not there, caching stays as numba has it.
    """
    extra = tuple(_stamp(Path(module.__file__)) for module in modules if module.__file__)
    for dispatcher in dispatchers:
        cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
        if cache_file is not None and hasattr(cache_file, "_source_stamp"):
            cache_file._source_stamp = (cache_file._source_stamp, extra)


def _stamp(path: Path) -> tuple[float, int]:
    """``(mtime, size)`` of a source file, as numba stamps the kernel's own file."""
    st = path.stat()
    return st.st_mtime, st.st_size


ensure_cache_dir()
