"""Result tables for people (a terminal table that fits its width) and machines (JSON, CSV).

A task's columns are its benchmark's result columns in order of importance; when a terminal
is too narrow for all of them, the least important ones are dropped (never cut into
unreadable cells) and a footnote names them and how to see everything.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

from rich.table import Table

#: Metrics that are counts (printed as integers, not percentages).
COUNT_METRICS = frozenset({"IDSW", "CLR_FP", "CLR_FN", "CLR_TP", "MT", "ML", "PT", "Frag"})
#: Columns shown for a task the table does not know: the first metrics found.
FALLBACK_COLUMNS = 8
#: Cell padding and borders rich adds per column.
_COLUMN_OVERHEAD = 3

Rows = Mapping[str, Mapping[str, float]]


def table_columns(columns: Sequence[str], rows: list[Mapping[str, float]]) -> list[str]:
    """The benchmark's ``columns`` that occur in ``rows`` (none given: the first metrics)."""
    present = {name for row in rows for name in row}
    if columns:
        return [name for name in columns if name in present]
    seen: list[str] = []
    for row in rows:
        seen += [key for key in row if key not in seen]
    return seen[:FALLBACK_COLUMNS]


def format_cell(name: str, value: float | None) -> str:
    """A metric as shown: percent with one decimal, counts as integers, '-' when missing."""
    if value is None or value != value:  # missing or NaN (nothing to score)
        return "-"
    if name in COUNT_METRICS:
        return f"{value:.0f}"
    return f"{100 * value:.1f}"


def _all_rows(per_sequence: Rows, combined: Mapping[str, float] | None,
              label: str = "COMBINED") -> dict[str, Mapping]:
    rows = dict(per_sequence)
    if combined:
        rows[label] = combined
    return rows


def _fit(columns: list[str], label_width: int, extra: int, width: int | None,
         cells: dict[str, int]) -> tuple[list[str], list[str]]:
    """Keep the leading columns that fit in ``width``; return (kept, dropped)."""
    if width is None:
        return columns, []
    used = label_width + _COLUMN_OVERHEAD + extra + 1
    kept: list[str] = []
    for name in columns:
        need = max(len(name), cells[name]) + _COLUMN_OVERHEAD
        if used + need > width and kept:
            break
        kept.append(name)
        used += need
    return kept, columns[len(kept):]


def metrics_table(
    per_sequence: Rows,
    combined: Mapping[str, float] | None,
    title: str,
    fps: Mapping[str, float] | None = None,
    columns: Sequence[str] = (),
    width: int | None = None,
    coverage: str = "",
) -> tuple[Table, list[str]]:
    """A rich table: one row per sequence plus COMBINED; returns (table, dropped columns).

    ``columns``: the benchmark's, most important first. With ``width`` (the terminal's),
    columns that would not fit are dropped, least important first. ``coverage``
    (``"7 of 7 sequences"``) labels the combined row.
    """
    label = f"COMBINED ({coverage})" if coverage else "COMBINED"
    rows = _all_rows(per_sequence, combined, label)
    shown = table_columns(columns, list(rows.values()))
    cells = {name: max((len(format_cell(name, r.get(name))) for r in rows.values()), default=1)
             for name in shown}
    label_width = max((len(name) for name in rows), default=8)
    extra = 8 + _COLUMN_OVERHEAD if fps is not None else 0
    kept, dropped = _fit(shown, label_width, extra, width, cells)
    table = Table(title=title, title_justify="left")
    table.add_column("sequence", no_wrap=True, min_width=min(label_width, 40))
    for name in kept:
        table.add_column(name, justify="right", no_wrap=True)
    if fps is not None:
        table.add_column("FPS", justify="right", no_wrap=True)
    for name, metrics in rows.items():
        values = [format_cell(column, metrics.get(column)) for column in kept]
        if fps is not None:
            values.append(f"{fps[name]:.1f}" if name in fps else "")
        table.add_row(name, *values, style="bold" if name == label else None)
    return table, dropped


def json_safe(value: Any) -> Any:
    """Replace NaN/inf floats (metrics of sequences with nothing to score) by None (null)."""
    if isinstance(value, dict):
        return {key: json_safe(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(item) for item in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def metrics_json(per_sequence: Rows, combined: Mapping[str, float] | None) -> str:
    """The metrics as JSON (NaN as null): ``{"per_sequence": ..., "combined": ...}``."""
    return json.dumps(json_safe({"per_sequence": dict(per_sequence),
                                 "combined": dict(combined or {})}), indent=2)


def metrics_csv(per_sequence: Rows, combined: Mapping[str, float] | None,
                columns: Sequence[str] = ()) -> str:
    """The metrics as CSV: a ``sequence`` column, then every metric (raw values)."""
    rows = _all_rows(per_sequence, combined)
    names = table_columns(columns, list(rows.values()))
    names += sorted({key for row in rows.values() for key in row} - set(names))
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["sequence", *names])
    for label, metrics in rows.items():
        writer.writerow([label, *(metrics.get(name, "") for name in names)])
    return buffer.getvalue()
