"""Per-attribute scores of run folders: a table (Markdown and CSV) and a radar chart (PNG, SVG).

A benchmark that tags its sequences with challenge attributes says so through
:meth:`~unitrack_env.benchmarks.base.Benchmark.sequence_attributes`. Each attribute's row
scores the run's result files of the sequences having it with the benchmark's own
:meth:`~unitrack_env.benchmarks.base.Benchmark.score_files` (so the combination rule is the
benchmark's: OTB's and LaSOT's mean over sequences), beside an ``Overall`` row of every
scored sequence. The radar draws the first reported metric (success AUC) per attribute, one
polygon per run. Same bytes for the same runs: no date, a fixed SVG salt.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from unitrack_env.io import atomic_write_text

from ..analysis.events import run_benchmark, run_sequences
from .figures import pyplot, save_figure

#: The row of every scored sequence.
OVERALL = "Overall"


@dataclass(frozen=True)
class AttributeRow:
    """One row of a run's attribute table: the sequences having ``code`` and their scores."""

    code: str
    name: str
    sequences: int
    values: dict[str, float]


@dataclass(frozen=True)
class RunAttributes:
    """A run's attribute table: its legend label, what it reports, the rows (Overall first)."""

    label: str
    metrics: tuple[str, ...]
    codes: tuple[str, ...]
    source: str
    rows: tuple[AttributeRow, ...]


def run_attributes(run: Path) -> RunAttributes | None:
    """The attribute table of one scored run folder (None: its benchmark tags none)."""
    bench = run_benchmark(run)
    sequences = run_sequences(run)
    attributes = bench.sequence_attributes(sequences)
    if attributes is None:
        return None
    spec = json.loads((run / "run.json").read_text(encoding="utf-8"))

    def row(code: str, name: str, having: list[str]) -> AttributeRow:
        combined = bench.score_files(run / "data", having).combined
        return AttributeRow(code, name, len(having),
                            {m: float(combined[m]) for m in attributes.metrics if m in combined})

    rows = [row(OVERALL, "every sequence", sequences)]
    for code, name in zip(attributes.codes, attributes.names, strict=True):
        having = [s for s in sequences if code in attributes.of.get(s, frozenset())]
        if having:
            rows.append(row(code, name, having))
    return RunAttributes(f"{run.name} ({spec.get('agent', '?')})", attributes.metrics,
                         attributes.codes, attributes.source, tuple(rows))


class NoAttributes(ValueError):
    """None of the runs' benchmarks tags its sequences with attributes."""


def load_attributes(runs: list[Path]) -> tuple[list[RunAttributes], list[Path]]:
    """The runs' attribute tables and the runs without attributes.

    NoAttributes when none has any; ValueError when two runs' benchmarks tag different ones.
    """
    tables, without = [], []
    for run in runs:
        table = run_attributes(run)
        if table is None:
            without.append(run)
        else:
            tables.append(table)
    if not tables:
        raise NoAttributes(f"no attributes for {', '.join(map(str, runs))}: their benchmarks tag "
                         "no sequence with attributes (OTB-2015, LaSOT with <root>/att/ and "
                         "UAV123 with anno/.../att/ do)")
    if len({t.codes for t in tables}) > 1:
        raise ValueError("the runs' benchmarks tag different attributes: give runs of one "
                         "benchmark")
    return tables, without


def _cell(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.1f}"


def _layout(tables: list[RunAttributes]) -> list[tuple[str, str, list[AttributeRow | None]]]:
    """``(code, name, each run's row or None)`` of every row any run has, in table order."""
    order = [OVERALL, *tables[0].codes]
    found = {(r.code, r.name) for t in tables for r in t.rows}
    out = []
    for code in order:
        name = next((n for c, n in found if c == code), None)
        if name is not None:
            rows = [next((r for r in t.rows if r.code == code), None) for t in tables]
            out.append((code, name, rows))
    return out


def markdown_table(tables: list[RunAttributes], without: list[Path] = ()) -> str:
    """One row per attribute (Overall first): its sequence count and each run's scores (%)."""
    several = len(tables) > 1
    head = ["Attribute", "Sequences"] + [f"{m} ({t.label})" if several else m
                                         for t in tables for m in t.metrics]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for code, name, rows in _layout(tables):
        counts = sorted({r.sequences for r in rows if r is not None})
        cells = [code if code == OVERALL else f"{code} ({name})",
                 " / ".join(map(str, counts))]
        cells += [_cell(r.values.get(m) if r else None) for r, t in zip(rows, tables,
                                                                        strict=True)
                  for m in t.metrics]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", f"Runs: {', '.join(t.label for t in tables)}. Percent; an attribute's row "
                  f"scores the sequences having it. Attributes: {tables[0].source}."]
    if without:
        lines.append(f"Left out (their benchmark tags no attributes): "
                     f"{', '.join(p.name for p in without)}.")
    return "\n".join(lines) + "\n"


def rows_csv(tables: list[RunAttributes]) -> str:
    """One CSV row per (run, attribute): its name, sequence count and metrics (fractions)."""
    metrics = list(dict.fromkeys(m for t in tables for m in t.metrics))
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["run", "attribute", "name", "sequences", *metrics])
    for table in tables:
        for row in table.rows:
            writer.writerow([table.label, row.code, row.name, row.sequences,
                             *(repr(row.values[m]) if m in row.values else "" for m in metrics)])
    return buffer.getvalue()


def write_attributes(tables: list[RunAttributes], without: list[Path], out: Path,
                     ) -> tuple[list[Path], str]:
    """Write ``attributes.md``, ``attributes.csv`` and the radar; return them and the table.

    ``tables`` and ``without``: :func:`load_attributes`'s.
    """
    out.mkdir(parents=True, exist_ok=True)
    text = markdown_table(tables, without)
    atomic_write_text(out / "attributes.md", text)
    atomic_write_text(out / "attributes.csv", rows_csv(tables))
    return [out / "attributes.md", out / "attributes.csv",
            *draw_attribute_radar(tables, out / "attributes-radar")], text


def draw_attribute_radar(tables: list[RunAttributes], stem: Path) -> list[Path]:
    """``<stem>.png`` and ``.svg``: the first metric per attribute, one polygon per run.

    [] without matplotlib, or with fewer than three attributes (no polygon to draw).
    """
    spokes = [(code, rows) for code, _, rows in _layout(tables) if code != OVERALL]
    if len(spokes) < 3:
        return []
    plt = pyplot("radar chart")
    if plt is None:
        return []
    return save_figure(_radar(plt, tables, spokes), stem, "unitrack-attributes")


def _radar(plt: Any, tables: list[RunAttributes],
           spokes: list[tuple[str, list[AttributeRow | None]]]) -> Any:
    metric = tables[0].metrics[0]
    angles = [2 * math.pi * i / len(spokes) for i in range(len(spokes))]
    figure, ax = plt.subplots(figsize=(5.8, 5.8), subplot_kw={"projection": "polar"})
    ax.set_theta_offset(math.pi / 2)
    ax.set_theta_direction(-1)
    for index, table in enumerate(tables):
        radius = [rows[index].values.get(metric, math.nan) if rows[index] else math.nan
                  for _, rows in spokes]
        color = plt.get_cmap("tab10")(index % 10)
        ax.plot([*angles, angles[0]], [*radius, radius[0]], color=color, linewidth=1.8,
                marker="o", markersize=4, label=table.label)
        ax.fill([*angles, angles[0]], [*radius, radius[0]], color=color, alpha=0.08)
    counts = [max((r.sequences for r in rows if r is not None), default=0)
              for _, rows in spokes]
    ax.set_xticks(angles)
    ax.set_xticklabels([f"{code}\n({n})" for (code, _), n in zip(spokes, counts, strict=True)],
                       fontsize=9)
    ax.set_ylim(0, 1.0)
    ax.set_yticks([0.25, 0.5, 0.75, 1.0])
    ax.set_yticklabels(["25", "50", "75", "100"], fontsize=7)
    ax.set_title(f"{metric} per attribute (sequences having it)", pad=20, fontsize=11)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.06), fontsize=8, frameon=False)
    return figure


__all__ = ["AttributeRow", "NoAttributes", "RunAttributes", "draw_attribute_radar",
           "load_attributes", "markdown_table", "rows_csv", "run_attributes", "write_attributes"]
