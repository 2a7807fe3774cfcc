"""The console progress bars and messages go to: stderr, so stdout stays one JSON object.

Core modules take it from here (never from :mod:`physinfer.cli`); the CLI shares it.
"""

from __future__ import annotations

from rich.console import Console

#: Progress bars, warnings and human-readable results (stdout is for ``--json``).
err_console = Console(stderr=True)
