"""Self-contained HTML reports: figures embedded as base64 PNG, tables, inline CSS.

Small helpers shared by the ``demo`` command and the case study::

    html = html_page("Title", [("<h2>Maps</h2>"), html_table(rows), img_tag(fig)])
    write_html("report.html", html)
"""

from __future__ import annotations

import base64
import html as _html
import io
import math
from collections.abc import Iterable, Sequence
from pathlib import Path

from ..io.atomic import atomic_write_text

__all__ = ["lead_block", "fig_to_png_bytes", "png_data_uri", "img_tag", "html_table", "html_page", "write_html", "esc"]

_CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; max-width: 1100px;
       margin: 2em auto; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { font-size: 1.6em; border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { font-size: 1.25em; margin-top: 1.6em; border-bottom: 1px solid #bbb; }
table { border-collapse: collapse; margin: .8em 0; font-size: .9em; }
th, td { border: 1px solid #ccc; padding: .25em .6em; text-align: right; }
th { background: #f0f0f0; } td:first-child, th:first-child { text-align: left; white-space: nowrap; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: .9em; color: #555; }
.note { background: #f7f7e8; border-left: 4px solid #cc9; padding: .5em 1em; font-size: .92em; }
code { background: #f3f3f3; padding: 0 .2em; }
table.wide { width: 100%; table-layout: fixed; }
table.wide th, table.wide td { white-space: normal; text-align: left; vertical-align: top; overflow-wrap: anywhere; }
.scroll { overflow-x: auto; max-width: 100%; }
section.lead { margin: .6em 0 1.2em; } section.lead figure { margin: .4em 0; }
p.verdict { font-size: 1.08em; background: #eef4fb; border-left: 4px solid #4a7ab5; padding: .45em 1em; margin: 0; }
"""


def esc(text) -> str:
    """HTML-escape ``str(text)``."""
    return _html.escape(str(text))


def fig_to_png_bytes(fig, *, dpi: int = 130) -> bytes:
    """Render a matplotlib figure to PNG bytes (Agg)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return buf.getvalue()


def png_data_uri(png: bytes) -> str:
    """``data:image/png;base64,...`` URI of PNG bytes."""
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def img_tag(fig_or_png, caption: str = "", *, dpi: int = 130) -> str:
    """A ``<figure>`` with the image embedded (a Figure or PNG bytes) and an optional caption."""
    png = fig_or_png if isinstance(fig_or_png, bytes | bytearray) else fig_to_png_bytes(fig_or_png, dpi=dpi)
    cap = f"<figcaption>{esc(caption)}</figcaption>" if caption else ""
    return f'<figure><img alt="{esc(caption)}" src="{png_data_uri(bytes(png))}">{cap}</figure>'


def lead_block(fig_or_png, caption: str, verdict_html: str, *, dpi: int = 130) -> str:
    """What every report opens with: its main figure and a one-sentence verdict (HTML, escaped by the caller)
    above it, before any table (``<section class="lead">``; tests/test_report_browser.py checks it comes first)."""
    figure = img_tag(fig_or_png, caption, dpi=dpi)
    return f'<section class="lead"><p class="verdict">{verdict_html}</p>{figure}</section>'


def _fmt(v, floatfmt: str, missing: str = "&ndash;") -> str:
    if v is None:
        return missing
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        if math.isnan(v):
            return missing
        return format(v, floatfmt)
    return esc(v)


def html_table(rows: Sequence[dict], columns: Iterable[str] | None = None, *, headers: dict | None = None,
               floatfmt: str = ".4g", missing: dict | None = None) -> str:
    """An HTML table of ``rows`` (dicts); ``columns`` selects/orders keys, ``headers`` renames them,
    ``missing`` says per column what a None / NaN cell means (default: a dash, never "NaN").  Wrapped in a
    horizontally scrolling block, so that a wide table never widens the page."""
    rows = list(rows)
    cols = list(columns) if columns is not None else (list(rows[0]) if rows else [])
    headers = headers or {}
    missing = missing or {}
    head = "".join(f"<th>{esc(headers.get(c, c))}</th>" for c in cols)
    body = "".join("<tr>" + "".join(f"<td>{_fmt(r.get(c), floatfmt, esc(missing.get(c, '')) or '&ndash;')}</td>"
                                    for c in cols) + "</tr>" for r in rows)
    return f'<div class="scroll"><table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>'


def html_page(title: str, parts: Iterable[str], *, css: str = _CSS) -> str:
    """A complete, self-contained HTML document: ``parts`` are HTML fragments, in order."""
    body = "\n".join(parts)
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<title>{esc(title)}</title><style>{css}</style></head>\n<body>\n<h1>{esc(title)}</h1>\n"
            f"{body}\n</body></html>\n")


def write_html(path, html: str) -> Path:
    """Write ``html`` (UTF-8), creating parent directories."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(p, html)
    return p
