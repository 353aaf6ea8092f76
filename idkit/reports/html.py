"""The pieces of idkit's HTML pages: one self-contained file each, opened without a network.

No template engine: a page is a few sections of escaped text, tables and figures. Everything is
inline — the style sheet in ``<style>``, every figure a PNG in a ``data:`` URI — so the file can be
mailed, archived or opened from a run folder on a machine without network access, and shows the
same thing in ten years. Numbers shown in a table cell carry their exact value in ``data-value``
(Python's ``repr``), so a reader (or a test) compares them with ``result.json`` without parsing a
rounded string.
"""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

#: The page's style: readable on screen and on paper, no web fonts (no network).
CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 2em auto;
       max-width: 70em; padding: 0 1em; color: #1d1d1f; line-height: 1.4; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; margin-top: 1.6em; }
h3 { margin-bottom: 0.3em; }
.meta { color: #555; font-size: 0.9em; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.92em; }
th, td { border: 1px solid #d6d6d6; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #f3f3f3; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
.good { background: #e3f4e3; } .fair { background: #fff4d6; } .poor { background: #fbe0e0; }
.badge { display: inline-block; padding: 0.05em 0.5em; border-radius: 0.6em; font-size: 0.85em;
         font-weight: 600; }
.badge.good { color: #1b5e20; } .badge.fair { color: #7a5200; } .badge.poor { color: #8e1c1c; }
.badge.none { background: #eee; color: #444; }
pre { background: #f6f6f6; padding: 0.6em; white-space: pre-wrap; font-size: 0.88em; }
img { max-width: 100%; } .rule { color: #555; font-size: 0.88em; }
details summary { cursor: pointer; }
"""


def escape(value: Any) -> str:
    """``value`` as text safe inside HTML."""
    return html.escape(str(value), quote=True)


def number(value: Any, digits: int = 6) -> str:
    """A number as people read it: ``digits`` significant digits; ``—`` for ``None``; ``inf``."""
    if value is None:
        return "—"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return escape(value)
    if math.isnan(value):
        return "n/a"
    if math.isinf(value):
        return "∞" if value > 0 else "−∞"
    return f"{value:.{digits}g}"


def percent(value: float | None, digits: int = 3) -> str:
    """A share as ``1.23 %`` (``—`` for ``None``, ``n/a`` for NaN)."""
    if value is None or not math.isfinite(value):
        return number(value)
    return f"{100 * value:.{digits}g} %"


class Cell:
    """A table cell: ``text`` (already HTML), its exact ``value`` for ``data-value``, a CSS class."""

    def __init__(self, text: str, value: Any = None, css: str = "") -> None:
        self.text, self.value, self.css = text, value, css

    def render(self, tag: str = "td") -> str:
        attributes = f' class="{self.css}"' if self.css else ""
        if self.value is not None:
            attributes += f' data-value="{escape(repr(self.value))}"'
        return f"<{tag}{attributes}>{self.text}</{tag}>"


def raw(markup: str, css: str = "") -> Cell:
    """A cell holding ``markup`` as it is (a badge, a link): not escaped."""
    return Cell(markup, None, css)


def num(value: Any, css: str = "", digits: int = 6, shown: str | None = None) -> Cell:
    """A numeric cell showing ``shown`` (default: :func:`number`) and carrying ``value`` exactly."""
    exact = float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None
    return Cell(shown if shown is not None else number(value, digits), exact, f"num {css}".strip())


def table(header: Sequence[str], rows: Iterable[Sequence[Any]], css: str = "") -> str:
    """A table; a row's items are :class:`Cell` objects or plain values (escaped)."""
    head = "".join(f"<th>{escape(h)}</th>" for h in header)
    body = []
    for row in rows:
        cells = [item if isinstance(item, Cell) else Cell(escape(item)) for item in row]
        body.append("<tr>" + "".join(c.render() for c in cells) + "</tr>")
    klass = f' class="{css}"' if css else ""
    return f"<table{klass}><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def badge(grade: str, text: str) -> str:
    """A coloured verdict: ``grade`` is ``good``, ``fair``, ``poor`` or ``none``."""
    return f'<span class="badge {grade}">{escape(text)}</span>'


def paragraph(text: str, css: str = "") -> str:
    klass = f' class="{css}"' if css else ""
    return f"<p{klass}>{escape(text)}</p>"


def preformatted(text: str) -> str:
    return f"<pre>{escape(text)}</pre>"


def listing(items: Iterable[str]) -> str:
    """A bulleted list of (already HTML) items."""
    return "<ul>" + "".join(f"<li>{item}</li>" for item in items) + "</ul>"


def section(anchor: str, heading: str, *parts: str) -> str:
    """``<section id=anchor>`` with a heading and its (already HTML) parts."""
    return f'<section id="{escape(anchor)}"><h2>{escape(heading)}</h2>{"".join(parts)}</section>'


def png(data: bytes, alt: str) -> str:
    """A PNG embedded as a ``data:`` URI (no file beside the page, no network)."""
    encoded = base64.b64encode(data).decode("ascii")
    return f'<img src="data:image/png;base64,{encoded}" alt="{escape(alt)}">'


def png_file(path: str | Path, alt: str) -> str:
    """The PNG at ``path`` embedded (:func:`png`), or a line saying it is missing."""
    try:
        return png(Path(path).read_bytes(), alt)
    except OSError:
        return paragraph(f"figure {Path(path).name} not found beside the report", "rule")


def collapsed(summary: str, body: str) -> str:
    """A ``<details>`` block, closed: for what a reader opens only when needed (the config)."""
    return f"<details><summary>{escape(summary)}</summary>{body}</details>"


def page(title: str, subtitle: str, sections: Iterable[str]) -> str:
    """The whole document: ``<!DOCTYPE html>``, inline style, title, sections."""
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{escape(title)}</title><style>{CSS}</style></head><body>"
        f'<header><h1>{escape(title)}</h1><p class="meta">{escape(subtitle)}</p></header>'
        + "".join(sections)
        + "</body></html>\n"
    )


def run_subtitle(document: Mapping[str, Any]) -> str:
    """Task, status, seed, run id, creation time and idkit version of a ``result.json`` document."""
    return (
        f"{document.get('task')} · status {document.get('status')} · seed {document.get('seed')} · run "
        f"{document.get('run_id')} · {document.get('created', '')} · idkit {document.get('idkit_version')}"
    )


def text_page(document: Mapping[str, Any], text: str, folder: str | Path) -> str:
    """The page of a task without a page of its own: its printed report and every PNG it wrote."""
    figures = [
        f"<h3>{escape(Path(path).name)}</h3>" + png_file(Path(folder) / Path(path).name, key)
        for key, path in (document.get("files") or {}).items()
        if str(path).endswith(".png")
    ]
    return page(
        str(document.get("label") or document.get("task")),
        run_subtitle(document),
        [
            section("report", "Report", preformatted(text)),
            *([section("figures", "Figures", *figures)] if figures else []),
        ],
    )
