"""A self-contained HTML report: figures embedded as base64 PNG, charts drawn by an embedded script;
no external resource, opens offline."""

from __future__ import annotations

import base64
import html
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

_STYLE = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#1b1f24;line-height:1.45}
h1{font-size:1.7em;margin-bottom:.2em}h2{border-bottom:2px solid #d0d7de;padding-bottom:.2em;margin-top:2em}
.lead{color:#57606a}figure{margin:1em 0}figure img{max-width:100%;border:1px solid #d0d7de}
figcaption{color:#57606a;font-size:.9em}table{border-collapse:collapse;margin:1em 0;font-size:.92em}
th,td{border:1px solid #d0d7de;padding:.3em .6em;text-align:right}th{background:#f6f8fa}
td:first-child,th:first-child{text-align:left}.ok{color:#1a7f37;font-weight:600}.bad{color:#cf222e;font-weight:600}
.note{background:#fff8c5;border:1px solid #d4a72c;padding:.5em .8em;border-radius:4px}
.zoom{border:1px solid #d0d7de;cursor:grab}.kpi{display:inline-block;margin:.3em 1.2em .3em 0}.kpi b{font-size:1.4em;display:block}
"""


@dataclass
class Section:
    """One chapter of the report: prose, key figures, tables and matplotlib figures."""

    title: str
    paragraphs: list[str] = field(default_factory=list)
    kpis: list[tuple[str, str]] = field(default_factory=list)
    tables: list[tuple[str, list[dict]]] = field(default_factory=list)
    figures: list[tuple[object, str]] = field(default_factory=list)
    """(matplotlib figure or path of a PNG, caption)."""
    notes: list[str] = field(default_factory=list)
    blocks: list[tuple[str, str]] = field(default_factory=list)
    """(HTML made by this package, e.g. an interactive chart; caption), after the figures."""


def figure_png_base64(figure, dpi: int = 110) -> str:
    """Render a matplotlib figure to a base64 PNG string and close it."""
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(figure)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def _png_base64(figure) -> str:
    """A matplotlib figure, or the path of a PNG a stage wrote, as base64."""
    if isinstance(figure, (str, Path)):
        return base64.b64encode(Path(figure).read_bytes()).decode("ascii")
    return figure_png_base64(figure)


def _cell(value) -> str:
    if isinstance(value, bool):
        return f'<span class="{"ok" if value else "bad"}">{"yes" if value else "no"}</span>'
    if isinstance(value, float):
        if value != value:
            return "–"
        return f"{value:,.0f}" if abs(value) >= 1000 else f"{value:.4g}"
    return html.escape("" if value is None else str(value))


def table_html(rows: list[dict]) -> str:
    if not rows:
        return ""
    columns = list(dict.fromkeys(k for row in rows for k in row))
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in columns)
    body = "".join("<tr>" + "".join(f"<td>{_cell(row.get(c))}</td>" for c in columns) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def render(title: str, lead: str, sections: list[Section]) -> str:
    """The whole document as one string."""
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>",
             f"<style>{_STYLE}</style></head><body><h1>{html.escape(title)}</h1><p class='lead'>{html.escape(lead)}</p>"]
    for number, section in enumerate(sections, 1):
        parts.append(f"<section><h2>{number}. {html.escape(section.title)}</h2>")
        if section.kpis:
            parts.append("<div>" + "".join(f"<span class='kpi'><b>{html.escape(v)}</b>{html.escape(k)}</span>"
                                           for k, v in section.kpis) + "</div>")
        parts.extend(f"<p>{html.escape(p)}</p>" for p in section.paragraphs)
        parts.extend(f"<p class='note'>{html.escape(n)}</p>" for n in section.notes)
        for caption, rows in section.tables:
            parts.append(f"<p><b>{html.escape(caption)}</b></p>{table_html(rows)}")
        for figure, caption in section.figures:
            parts.append(f"<figure><img alt='{html.escape(caption)}' src='data:image/png;base64,"
                         f"{_png_base64(figure)}'><figcaption>{html.escape(caption)}</figcaption></figure>")
        for block, caption in section.blocks:
            parts.append(f"<figure>{block}<figcaption>{html.escape(caption)}</figcaption></figure>")
        parts.append("</section>")
    parts.append("</body></html>")
    return "".join(parts)


def figures_present(out_dir: Path, names: list[tuple[str, str]]) -> list[tuple[Path, str]]:
    """(path, caption) of each named figure that exists in ``out_dir``."""
    return [(out_dir / name, caption) for name, caption in names if (out_dir / name).is_file()]


def deviation_pct(measured, generated) -> str:
    """Generated relative to measured, as a signed percentage ("–" where undefined)."""
    if measured is None or generated is None or not math.isfinite(measured) or not math.isfinite(generated) \
            or measured == 0:
        return "–"
    return f"{(generated / measured - 1) * 100:+.1f} %"
