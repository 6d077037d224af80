"""HTML pieces of the report: page frame with inline CSS and JS, tables, SVG timelines.

Everything is inline (no CDN, no fonts, no scripts from elsewhere), so ``index.html`` opens
from ``file://`` offline. Tables with class ``sortable`` sort on a header click: numbers by
their ``data-value``, text otherwise.
"""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Sequence

import numpy as np
import pandas as pd

CSS = """
body{font:14px/1.4 system-ui,sans-serif;margin:1.5em auto;max-width:1200px;color:#222;
padding:0 1em}
h1{font-size:1.5em}h2{border-bottom:1px solid #ccc;margin-top:1.6em}
table{border-collapse:collapse;margin:.5em 0}td,th{padding:.2em .6em;border:1px solid #ddd;
text-align:right}td:first-child,th:first-child,td.text,th.text{text-align:left}
th{background:#f3f3f3;cursor:pointer;user-select:none}th[aria-sort=ascending]::after{content:" ▲"}
th[aria-sort=descending]::after{content:" ▼"}tr.combined td{font-weight:bold}
.sig{background:#e8f5e9}.note{color:#a33}.legend span{display:inline-block;width:1em;
height:.8em;margin:0 .3em 0 1em;vertical-align:middle}
.thumbs{display:flex;flex-wrap:wrap;gap:6px}.thumbs figure{margin:0;width:220px;
font-size:12px}.thumbs img{width:220px;display:block;border:1px solid #999}
svg.timeline{display:block;margin:.3em 0}svg text{font:11px sans-serif}
svg.forest text{font:13px sans-serif}
"""

JS = """
function sortTable(th){const table=th.closest('table'),body=table.tBodies[0];
const idx=Array.prototype.indexOf.call(th.parentNode.children,th);
const asc=th.getAttribute('aria-sort')!=='ascending';
for(const h of th.parentNode.children)h.removeAttribute('aria-sort');
th.setAttribute('aria-sort',asc?'ascending':'descending');
const rows=Array.from(body.rows);const key=r=>{const c=r.cells[idx];
const v=c.getAttribute('data-value');return v===null?c.textContent:parseFloat(v)};
rows.sort((a,b)=>{const x=key(a),y=key(b);let d;
if(typeof x==='number'&&typeof y==='number'){d=(isNaN(x)?-Infinity:x)-(isNaN(y)?-Infinity:y)}
else{d=String(x).localeCompare(String(y))}return asc?d:-d});
for(const r of rows)body.appendChild(r)}
document.querySelectorAll('table.sortable th').forEach(th=>th.addEventListener('click',
()=>sortTable(th)));
"""


def esc(value: object) -> str:
    """HTML-escaped text."""
    return html.escape(str(value), quote=True)


def page(title: str, body: Iterable[str]) -> str:
    """A whole HTML document with the inline CSS and JS."""
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<meta name=\"viewport\" content=\"width=device-width\">"
            f"<meta name=\"generator\" content=\"unitrack-env\">"
            f"<title>{esc(title)}</title><style>{CSS}</style></head><body>\n"
            + "\n".join(body) + f"\n<script>{JS}</script></body></html>\n")


def number_cell(value: float | None, *, percent: bool) -> str:
    """A table cell sorting by the raw value, shown in percent or as a count."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return '<td data-value="NaN">-</td>'
    text = f"{100 * value:.1f}" if percent else f"{value:.0f}"
    return f'<td data-value="{value!r}">{text}</td>'


def table(headers: Sequence[str], rows: Iterable[str], *, table_id: str,
          sortable: bool = True) -> str:
    """A table from header names and ready ``<tr>`` rows."""
    cls = ' class="sortable"' if sortable else ""
    head = "".join(f'<th scope="col"{" class=text" if i < 2 else ""}>{esc(h)}</th>'
                   for i, h in enumerate(headers))
    return (f'<table id="{esc(table_id)}"{cls}><thead><tr>{head}</tr></thead><tbody>'
            + "".join(rows) + "</tbody></table>")


#: Lanes of a MOT timeline: event type, colour, label.
MOT_LANES = (("fn", "#e67e22", "misses (FN)"), ("fp", "#8e44ad", "false positives"),
             ("idsw", "#c0392b", "ID switches"), ("frag", "#2980b9", "fragmentations"))


def mot_timeline(events: pd.DataFrame, num_frames: int, width: int = 1000,
                 max_bars: int = 800, kinds: Sequence[str] | None = None) -> str:
    """An SVG with one lane per MOT event type (or those of ``kinds``), bar height = count.

    One bar per frame, or per bin of frames on a long sequence, so the page stays small.
    """
    lanes = [lane for lane in MOT_LANES if kinds is None or lane[0] in kinds]
    lane, label_w = 26, 110
    height = lane * len(lanes) + 18
    size = max(1, math.ceil(num_frames / max_bars))  # frames per bar
    scale = (width - label_w) / max(1, num_frames)
    parts = [f'<svg class="timeline" width="{width}" height="{height}" '
             f'viewBox="0 0 {width} {height}" role="img" aria-label="error events over time">']
    for i, (kind, colour, label) in enumerate(lanes):
        y0 = i * lane
        frames = events.loc[events["type"] == kind, "frame"].to_numpy(dtype=np.int64)
        counts = pd.Series((frames - 1) // size).value_counts()
        top = max(1, int(counts.max())) if len(counts) else 1
        parts.append(f'<text x="0" y="{y0 + 16}">{esc(label)} ({len(frames)})</text>')
        parts.append(f'<line x1="{label_w}" x2="{width}" y1="{y0 + lane - 2}" '
                     f'y2="{y0 + lane - 2}" stroke="#ccc"/>')
        for start, count in counts.items():
            h = max(2.0, (lane - 6) * count / top)
            x = label_w + int(start) * size * scale
            first = int(start) * size + 1
            where = f"frame {first}" if size == 1 else f"frames {first}-{first + size - 1}"
            parts.append(f'<rect class="ev-{kind}" x="{x:.1f}" y="{y0 + lane - 2 - h:.1f}" '
                         f'width="{max(1.0, size * scale):.1f}" height="{h:.1f}" '
                         f'fill="{colour}"><title>{where}: {int(count)} {kind}</title></rect>')
    parts.append(_axis(num_frames, label_w, width, lane * len(lanes) + 14))
    parts.append("</svg>")
    return "".join(parts)


def value_timeline(values: pd.Series, frames: pd.Series, label: str, num_frames: int,
                   width: int = 1000) -> str:
    """An SVG line of a per-frame value in [0, 1] (SOT IoU, VOS J, pose PCK)."""
    label_w, h = 110, 60
    scale = (width - label_w) / max(1, num_frames)
    means = pd.DataFrame({"f": frames, "v": values}).groupby("f")["v"].mean()
    points = " ".join(f"{label_w + (int(f) - 1) * scale:.1f},{h - 4 - (h - 8) * float(v):.1f}"
                      for f, v in means.items() if np.isfinite(v))
    return (f'<svg class="timeline" width="{width}" height="{h + 18}" role="img" '
            f'aria-label="{esc(label)} per frame"><text x="0" y="{h / 2}">{esc(label)}</text>'
            f'<rect x="{label_w}" y="4" width="{width - label_w}" height="{h - 8}" '
            f'fill="none" stroke="#ccc"/><polyline points="{points}" fill="none" '
            f'stroke="#c0392b"/>{_axis(num_frames, label_w, width, h + 14)}</svg>')


def _axis(num_frames: int, left: int, width: int, y: int) -> str:
    step = max(1, 10 ** int(math.log10(max(1, num_frames))) // 2)
    if num_frames / step > 12:
        step *= 2
    scale = (width - left) / max(1, num_frames)
    ticks = [f'<text x="{left + (t - 1) * scale:.1f}" y="{y}">{t}</text>'
             for t in range(1, num_frames + 1, step)]
    return "".join(ticks)


def _ticks(half: float) -> list[float]:
    """Round tick values in percent points covering [-half, +half] (half in fractions)."""
    span = 100 * half
    step = 10 ** math.floor(math.log10(max(span, 1e-6)))
    for factor in (1, 2, 5, 10):
        if span / (step * factor) <= 4:
            step *= factor
            break
    count = int(span // step)
    return [i * step for i in range(-count, count + 1)]


def forest(rows: dict, metrics: Sequence[str], width: int = 760) -> str:
    """An SVG of each metric's combined difference A - B with its 95% interval.

    One row per metric with its numbers beside it, a zero line, an axis labelled in percent
    points; rows whose interval excludes 0 in red.
    """
    spans = [abs(v) for m in metrics for v in (rows[m].low, rows[m].high, rows[m].diff)]
    half = max(1e-3, max(spans, default=0.01)) * 1.1
    line_h, left, right, top = 28, 70, 190, 22
    plot_bottom = top + line_h * len(metrics)
    height = plot_bottom + 44
    x = lambda v: left + (v + half) / (2 * half) * (width - left - right)  # noqa: E731
    parts = [f'<svg class="forest" width="{width}" height="{height}" role="img" '
             'aria-label="differences A - B with 95% intervals">',
             f'<text x="{left}" y="14" font-weight="bold">A - B, combined (95% interval)</text>']
    for tick in _ticks(half):
        tx = x(tick / 100)
        zero = abs(tick) < 1e-9
        parts.append(f'<line x1="{tx:.1f}" x2="{tx:.1f}" y1="{top}" y2="{plot_bottom}" '
                     f'stroke="{"#333" if zero else "#e3e3e3"}" '
                     f'stroke-width="{2 if zero else 1}"/>'
                     f'<text x="{tx:.1f}" y="{plot_bottom + 14}" text-anchor="middle">'
                     f"{'0' if zero else f'{tick:+g}'}</text>")
    parts.append(f'<text x="{x(0):.1f}" y="{plot_bottom + 30}" text-anchor="middle">'
                 "A - B in percent points (0: no difference; right: A higher)</text>")
    for i, m in enumerate(metrics):
        d, y = rows[m], top + line_h * i + line_h / 2
        ink = "#c0392b" if d.significant else "#555"
        parts.append(f'<g class="forest-row" data-metric="{esc(m)}">'
                     f'<text x="0" y="{y + 4:.1f}" font-weight="bold">{esc(m)}</text>'
                     f'<line x1="{x(d.low):.1f}" x2="{x(d.high):.1f}" y1="{y:.1f}" '
                     f'y2="{y:.1f}" stroke="{ink}" stroke-width="3"/>'
                     f'<circle cx="{x(d.diff):.1f}" cy="{y:.1f}" r="5" fill="{ink}"/>'
                     f'<text x="{width - right + 12}" y="{y + 4:.1f}">{100 * d.diff:+.1f} '
                     f"[{100 * d.low:+.1f}, {100 * d.high:+.1f}]</text></g>")
    parts.append("</svg>")
    return "".join(parts)
