"""One self-contained page per run: ``report.html``.

Every ``refine``, ``diagnose`` and ``infer`` run writes ``report.html`` into its output
folder: the parameter table (best fit, median and 90 % interval, label, truth and error
where known), the refinement plot, the side-by-side video, the noise floor, the diagnosis
verdict and maps, and the run's settings. Images and videos are inlined as ``data:`` URIs,
so the one file can be mailed or archived alone. ``physinfer report RUN_DIR`` rebuilds it.

Importing this package is cheap (standard library only).
"""

from physinfer.report.page import (
    REPORT_FILE,
    Report,
    build_report,
    run_kind,
    write_report,
    write_report_quietly,
)

__all__ = [
    "REPORT_FILE",
    "Report",
    "build_report",
    "run_kind",
    "write_report",
    "write_report_quietly",
]
