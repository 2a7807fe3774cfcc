"""Small HTML building blocks for the run page: tables, inlined figures and videos, the shell.

Every piece of text goes through :func:`html.escape`; images and videos are inlined as
``data:`` URIs, so the page opens anywhere with no network and no files beside it. A
Content-Security-Policy in the page forbids every outside resource, so a browser would
report one that slipped in.
"""

from __future__ import annotations

import base64
import math
from collections.abc import Iterable, Mapping, Sequence
from html import escape
from pathlib import Path
from typing import Any

#: Videos larger than this are linked, not inlined (base64 makes them 4/3 as large again).
MAX_INLINE_VIDEO_BYTES = 16 * 1024 * 1024
#: Images larger than this are linked, not inlined.
MAX_INLINE_IMAGE_BYTES = 8 * 1024 * 1024

_MIME = {
    ".png": "image/png",
    ".jpg": "image/jpeg",
    ".jpeg": "image/jpeg",
    ".mp4": "video/mp4",
    ".webm": "video/webm",
}

CSS = """
body{font:15px/1.45 system-ui,-apple-system,"Segoe UI",sans-serif;color:#1d2330;background:#f6f7f9;margin:0}
main{max-width:1080px;margin:0 auto;padding:1.5em 1.2em 3em}
h1{font-size:1.5em;margin:0 0 .2em}h2{font-size:1.15em;margin:1.8em 0 .5em;border-bottom:1px solid #d5d9e0}
.sub{color:#5a6272;margin:0 0 1em}.note{color:#5a6272;font-size:.92em}
table{border-collapse:collapse;background:#fff;font-size:.92em;margin:.3em 0}
th,td{padding:.3em .7em;border:1px solid #dde1e7;text-align:left;vertical-align:top}
th{background:#eef0f4;font-weight:600}td.num{text-align:right;font-variant-numeric:tabular-nums}
.verdict{background:#fff;border-left:5px solid #4a7bd0;padding:.6em 1em;margin:.6em 0}
.verdict.bad{border-color:#d0574a}.verdict.good{border-color:#3f9b5a}
figure{margin:.5em 0}figure img,video{max-width:100%;background:#fff;border:1px solid #dde1e7}
figcaption{color:#5a6272;font-size:.9em}code{font-size:.9em}
"""

#: Nothing but inlined data and the page's own style may load.
CSP = "default-src 'none'; img-src data:; media-src data:; style-src 'unsafe-inline'"


def fmt(value: Any) -> str:
    """A value as short display text: 4 significant digits, ``—`` for none, yes/no."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return "—" if not math.isfinite(value) else f"{value:.4g}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(fmt(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {fmt(v)}" for k, v in value.items()) + "}"
    return str(value)


def interval(pair: Sequence[float] | None) -> str:
    """``[low, high]`` as ``low – high``."""
    return "—" if not pair else f"{fmt(float(pair[0]))} – {fmt(float(pair[1]))}"


def table(headers: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """An HTML table; numbers are right-aligned and formatted by :func:`fmt`."""
    head = "".join(f"<th>{escape(h)}</th>" for h in headers)
    body = []
    for row in rows:
        cells = []
        for cell in row:
            cls = (
                ' class="num"'
                if isinstance(cell, (int, float)) and not isinstance(cell, bool)
                else ""
            )
            cells.append(f"<td{cls}>{escape(fmt(cell))}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def key_values(items: Mapping[str, Any]) -> str:
    """A two-column table of settings (nested values shown as compact JSON)."""
    return table(("setting", "value"), ((k, v) for k, v in items.items()))


def paragraph(text: str, cls: str = "") -> str:
    """One escaped paragraph."""
    attr = f' class="{escape(cls)}"' if cls else ""
    return f"<p{attr}>{escape(text)}</p>"


def section(title: str, *parts: str) -> str:
    """A titled section of already-built HTML parts."""
    return f"<section><h2>{escape(title)}</h2>{''.join(parts)}</section>"


def data_uri(path: Path) -> str:
    """The file as a base64 ``data:`` URI (its MIME type from the suffix)."""
    mime = _MIME.get(path.suffix.lower(), "application/octet-stream")
    return f"data:{mime};base64,{base64.b64encode(path.read_bytes()).decode('ascii')}"


def _missing_or_large(path: Path, limit: int, what: str) -> str | None:
    """A note when ``path`` cannot be inlined (absent or over ``limit``), else ``None``."""
    if not path.is_file():
        return paragraph(f"no {what} ({path.name} is not in the run folder)", "note")
    size = path.stat().st_size
    if size > limit:
        return (
            f'<p class="note">{escape(path.name)} is {size / 2**20:.1f} MiB, too large to inline '
            f'(limit {limit / 2**20:.0f} MiB): <a href="{escape(path.name)}">open it beside this page</a>.</p>'
        )
    return None


def figure(path: Path, caption: str) -> str:
    """An inlined image with a caption, or a note saying why it is not shown."""
    note = _missing_or_large(path, MAX_INLINE_IMAGE_BYTES, caption)
    if note is not None:
        return note
    return (
        f'<figure><img src="{data_uri(path)}" alt="{escape(caption)}">'
        f"<figcaption>{escape(caption)} ({escape(path.name)})</figcaption></figure>"
    )


def video(path: Path, caption: str) -> str:
    """An inlined, looping, muted video with a caption, or a note saying why it is not shown."""
    note = _missing_or_large(path, MAX_INLINE_VIDEO_BYTES, caption)
    if note is not None:
        return note
    return (
        f'<figure><video controls muted loop playsinline preload="auto" src="{data_uri(path)}"></video>'
        f"<figcaption>{escape(caption)} ({escape(path.name)})</figcaption></figure>"
    )


def page(title: str, subtitle: str, body: Sequence[str], footer: str) -> str:
    """The whole document: one file, UTF-8, no outside resources."""
    return (
        "<!doctype html>\n"
        '<html lang="en"><head><meta charset="utf-8">'
        f'<meta http-equiv="Content-Security-Policy" content="{CSP}">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{escape(title)}</title><style>{CSS}</style></head>\n"
        f"<body><main><h1>{escape(title)}</h1>{paragraph(subtitle, 'sub')}\n"
        + "\n".join(body)
        + f"\n<footer>{paragraph(footer, 'note')}</footer></main></body></html>\n"
    )
