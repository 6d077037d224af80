"""Build the static HTML report of run folders (``unitrack report``), without replaying agents.

``index.html`` holds the sortable metrics table, the paired comparison of the first two runs,
and per run and sequence an event timeline with thumbnails of its events (ID switches, bursts
of misses or of failed frames; linked to the event's page and to a ``unitrack render`` clip
when one is in the run folder). Each sequence has its own page and each pictured event one
(pages.py). A scorecard folder gives its table and radar chart.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from typing import Any

import pandas as pd

from unitrack_env.io import atomic_write_bytes, atomic_write_text, refuse_link

from ..analysis.events import load_events, run_benchmark, run_sequences
from ..analysis.intervals import comparable, compare_runs
from ..plots.attributes import NoAttributes, draw_attribute_radar, load_attributes
from ..plots.curves import draw_labelled
from ..run.integrity import DifferentData, check_current
from ..scorecard.correlation_plot import figure_stem
from ..scorecard.plan import BASELINE
from ..scorecard.table import columns, value
from .html import esc, forest, mot_timeline, number_cell, page, table, value_timeline
from .pages import event_pages, figure, legend, sequence_page
from .pictures import choose, event_pictures

#: Count metrics (shown as integers, not percent).
COUNTS = {"IDSW", "CLR_FP", "CLR_FN", "MT", "ML", "Frag", "IDs", "CLR_TP"}

def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", text).strip("-") or "x"


def metrics_section(runs: list[tuple[str, Path, Any, dict]]) -> str:
    """The sortable table of every run's per-sequence and combined metrics."""
    columns: list[str] = []
    for _, _, bench, metrics in runs:
        for col in bench.columns:
            if col not in columns and any(col in row for row in metrics["per_sequence"].values()):
                columns.append(col)
    rows = []
    for label, _, _, metrics in runs:
        entries = [*metrics["per_sequence"].items(), ("COMBINED", metrics.get("combined", {}))]
        for seq, values in entries:
            cls = ' class="combined"' if seq == "COMBINED" else ""
            cells = "".join(number_cell(values.get(c), percent=c not in COUNTS) for c in columns)
            rows.append(f'<tr{cls} data-sequence="{esc(seq)}" data-run="{esc(label)}">'
                        f'<td class="text">{esc(label)}</td><td class="text">{esc(seq)}</td>'
                        f"{cells}</tr>")
    return ("<h2 id=\"metrics\">Metrics</h2><p>Percent, counts as integers; click a header "
            "to sort.</p>" + table(["run", "sequence", *columns], rows, table_id="metrics-table"))


def curves_section(runs: list[tuple[str, Path, Any, dict]], out: Path) -> str:
    """The runs' success and precision plots, when their benchmarks draw any ("" if none)."""
    labelled = [(label, bench.curves(run / "data", list(metrics.get("per_sequence", {}))))
                for label, run, bench, metrics in runs]
    if not any(curves for _, curves in labelled):
        return ""
    images = "".join(f'<img src="{p.name}" alt="{esc(p.stem)}" style="max-width:460px">'
                     for p in draw_labelled(labelled, out, prefix="curves-")
                     if p.suffix == ".svg")
    return '<h2 id="curves">Success and precision plots</h2><p>' + images + "</p>"


def attributes_section(runs: list[tuple[str, Path, Any, dict]], out: Path) -> str:
    """Each run's scores per challenge attribute and their radar ("" if no run has any)."""
    if not any(bench.sequence_attributes(list(metrics.get("per_sequence", {})))
               for _, _, bench, metrics in runs):
        return ""  # most tasks
    try:
        tables, without = load_attributes([run for _, run, _, _ in runs])
    except NoAttributes:
        return ""
    except ValueError as exc:  # two benchmarks' different attributes
        return f'<h2 id="attributes">Attributes</h2><p class="note">{esc(str(exc))}</p>'
    metrics = list(dict.fromkeys(m for t in tables for m in t.metrics))
    rows = [f'<tr><td class="text">{esc(t.label)}</td><td class="text">{esc(r.code)}</td>'
            f'<td data-value="{r.sequences}">{r.sequences}</td>'
            + "".join(number_cell(r.values.get(m), percent=True) for m in metrics) + "</tr>"
            for t in tables for r in t.rows]
    images = "".join(f'<img src="{p.name}" alt="attribute radar" style="max-width:460px">'
                     for p in draw_attribute_radar(tables, out / "attributes-radar")
                     if p.suffix == ".svg")
    note = f"Attributes: {tables[0].source}." + (
        f" No attributes: {', '.join(p.name for p in without)}." if without else "")
    return ('<h2 id="attributes">Attributes</h2><p>Each row scores the sequences having the '
            f"attribute. {esc(note)}</p>" + images
            + table(["run", "attribute", "sequences", *metrics], rows, table_id="attributes-table"))


def compare_section(run_a: Path, run_b: Path, resamples: int) -> str:
    """The paired comparison of two runs (whose benchmark states intervals) with 95% intervals."""
    comp = compare_runs(run_a, run_b, resamples=resamples)
    rows = []
    for seq, row in comp.rows.items():
        for metric, d in row.items():
            cls = ' class="sig"' if d.significant else ""
            rows.append(f'<tr{cls} data-sequence="{esc(seq)}"><td class="text">{esc(seq)}</td>'
                        f'<td class="text">{esc(metric)}</td>'
                        + number_cell(d.a, percent=True) + number_cell(d.b, percent=True)
                        + number_cell(d.diff, percent=True)
                        + f'<td data-value="{d.low!r}">[{100 * d.low:+.1f}, '
                          f'{100 * d.high:+.1f}]{"" if d.reliable else " (too little data)"}'
                          "</td></tr>")
    notes = "".join(f'<p class="note">{esc(n)}</p>' for n in comp.notes)
    metrics = list(comp.rows["COMBINED"])
    return (f'<h2 id="compare">Comparison</h2><p>A = {esc(run_a.name)}, B = {esc(run_b.name)}: '
            f"paired delete-a-block jackknife over frames (blocks of "
            f"{', '.join(f'{b}' for b in comp.blocks.values())} frames); shaded rows: the "
            "95% interval of A - B excludes 0.</p>" + notes
            + forest(comp.rows["COMBINED"], metrics)
            + table(["sequence", "metric", "A", "B", "A-B", "95% interval"], rows,
                    table_id="compare-table"))


def _clip(run: Path, sequence: str) -> Path | None:
    clips = sorted(p for p in run.rglob("*.mp4") if p.stem.startswith(sequence))
    return clips[0] if clips else None


def _timeline(bench: Any, events: pd.DataFrame, frames: int) -> str:
    """A sequence's timeline, drawn as its benchmark's ``report_view`` says."""
    view = bench.report_view
    if view.thumbnails:  # box MOT: the event lanes alone
        return mot_timeline(events, frames, kinds=view.lanes)
    body = ""
    if view.lanes:
        body = mot_timeline(events, frames, kinds=view.lanes) + f"<p>Counts are {view.unit}.</p>"
    column, name = view.value or (None, None)
    if column is not None and column in events:
        rows = events[events["type"] == view.value_type] if view.value_type else events
        body += value_timeline(rows[column], rows["frame"], name, frames)
    return body or "<p>No per-frame events.</p>"


def sequence_section(index: int, label: str, run: Path, bench: Any, seq: str,
                     events: pd.DataFrame, out: Path, limit: int) -> str:
    """A run's sequence on the index (timeline, thumbnails) and its own page and event pages."""
    frames = bench.sequence_length(seq)
    title = f"{label} · {seq} ({frames} frames)"
    timeline = _timeline(bench, events, frames)
    pictures = event_pictures(bench, run, seq, events, out / f"img{index}-{_slug(seq)}", limit)
    clip = _clip(run, seq)
    figures = [figure(p, clip) for p in pictures]
    name = sequence_page(out, f"seq{index}-{_slug(seq)}.html", title, timeline, figures,
                         choose(events, len(events)), pictures,
                         f"unitrack events {run} --sequence {seq} --format csv")
    event_pages(out, pictures, name, title)
    shown = (f"<p>{len(figures)} pictures (at most {limit} of each kind of event, sampled "
             "evenly over the sequence); every event on the sequence's page.</p>" if figures
             else "<p>No event to picture (or the frames are not on this machine).</p>")
    return (f'<section class="sequence" data-sequence="{esc(seq)}">'
            f'<h3 id="{_slug(label)}-{_slug(seq)}"><a class="sequence-link" '
            f'href="{esc(name)}">{esc(title)}</a></h3>' + timeline + shown
            + '<div class="thumbs">' + "".join(figures) + "</div></section>")


def correlation_section(folder: Path, out: Path) -> str:
    """The HTML of a scorecard folder's correlation study ("" when it has none)."""
    path = folder / "correlation.json"
    if not path.is_file():
        return ""
    result = json.loads(path.read_text(encoding="utf-8"))
    html = ["<h2 id=\"correlation\">Correlation study</h2>"]
    for name in result["metrics"]:
        rows = []
        for c in (c for c in result["correlations"] if c["metric"] == name):
            cells = [c["title"], str(c["n"])]
            for key in ("pearson", "spearman"):
                ci = c[f"{key}_ci"]
                cells.append("-" if c[key] is None else f"{c[key]:+.2f}" + (
                    f" [{ci[0]:+.2f}, {ci[1]:+.2f}]" if ci else ""))
            rows.append("<tr>" + "".join(f'<td class="text">{esc(v)}</td>'
                                         for v in [*cells, c["verdict"]]) + "</tr>")
        html.append(f"<h3>{esc(name)}</h3>" + table(
            ["task", "models", "Pearson r [95%]", "Spearman rho [95%]", "verdict"], rows,
            table_id=f"correlation-{figure_stem(name)}"))
        src = folder / f"correlation-{figure_stem(name)}.svg"
        if src.is_file():
            shutil.copyfile(src, out / src.name)
            html.append(f'<p><img src="{esc(src.name)}" alt="correlation with {esc(name)}" '
                        'style="max-width:100%"></p>')
    return "".join(html)


def scorecard_section(folder: Path, out: Path) -> str:
    """A scorecard folder's table (its Markdown as HTML) and radar chart."""
    card = json.loads((folder / "scorecard.json").read_text(encoding="utf-8"))
    cols = columns(card)
    rows = []
    for model in [*card["models"], BASELINE]:
        cells = "".join(number_cell(value(card, model, t, h, m), percent=m not in COUNTS)
                        for t, h, m in cols)
        rows.append(f'<tr data-sequence="{esc(model)}"><td class="text">{esc(model)}</td>'
                    f'<td class="text">{len(cols)} columns</td>{cells}</tr>')
    headers = ["representation", "", *(f"{t} {m} ({h})" for t, h, m in cols)]
    radar = ""
    for ext in ("svg", "png"):
        src = folder / f"scorecard.{ext}"
        if src.is_file():
            atomic_write_bytes(out / src.name, src.read_bytes())
            radar = f'<p><img src="{src.name}" alt="radar chart" style="max-width:600px"></p>'
            break
    return ('<h2 id="scorecard">Scorecard</h2>' + table(headers, rows, table_id="metrics-table")
            + radar + _card_intervals(folder) + correlation_section(folder, out))


def _card_intervals(folder: Path) -> str:
    """The cells' 95% intervals when the scorecard was made with ``--ci``."""
    path = folder / "scorecard_ci.json"
    if not path.is_file():
        return ""
    rows = []
    for c in json.loads(path.read_text(encoding="utf-8")):
        ci = "-" if c["low"] is None else f"[{100 * c['low']:.1f}, {100 * c['high']:.1f}]"
        rows.append(f'<tr><td class="text">{esc(c["model"])}</td><td class="text">'
                    f'{esc(c["task"])} {esc(c["head"])}</td><td>{esc(c["metric"])}</td>'
                    + number_cell(c["value"], percent=True) + f"<td>{ci}</td></tr>")
    return ("<h3>95% intervals (block bootstrap over frames)</h3>"
            + table(["model", "cell", "metric", "value", "95% interval"], rows,
                    table_id="ci-table"))


def build_report(runs: list[Path], out: Path, *, thumbnails: int = 24,
                 resamples: int = 500) -> Path:
    """Write ``out/index.html`` for run folders (or one scorecard folder); return its path.

    Raises:
        FileExistsError: ``out`` holds an ``index.html`` (or radar chart) that is not an
            earlier report's; nothing of the user's is replaced.
        StaleRun: a run's result or data files changed after scoring. Two runs scored
            against different data get a note instead of a comparison.
    """
    check_report_folder(out)
    out.mkdir(parents=True, exist_ok=True)
    if len(runs) == 1 and (runs[0] / "scorecard.json").is_file():
        body = [f"<h1>Scorecard report: {esc(runs[0].name)}</h1>",
                scorecard_section(runs[0], out)]
        return _write(out, "unitrack scorecard report", body)
    loaded = []
    for run in runs:
        metrics_path = run / "metrics.json"
        if not metrics_path.is_file():
            raise FileNotFoundError(f"{metrics_path}: not a finished run of `unitrack evaluate`")
        spec = json.loads((run / "run.json").read_text(encoding="utf-8"))
        label = f"{run.name} ({spec.get('agent', '?')})"
        run_sequences(run)  # its sequence names are checked before any is used as a path
        metrics = json.loads(metrics_path.read_text(encoding="utf-8"))
        bench = run_benchmark(run)
        check_current(run, bench, list(metrics.get("per_sequence", {})))  # else: StaleRun
        loaded.append((label, run, bench, metrics))
    body = [f"<h1>unitrack report: {esc(', '.join(r.name for r in runs))}</h1>",
            "<p>" + esc(", ".join(f"{lab}: {b.name}" for lab, _, b, _ in loaded)) + "</p>",
            metrics_section(loaded), curves_section(loaded, out),
            attributes_section(loaded, out)]
    if (len(loaded) >= 2 and loaded[0][2].task == loaded[1][2].task
            and comparable(loaded[0][2])):
        common = set(loaded[0][3]["per_sequence"]) & set(loaded[1][3]["per_sequence"])
        try:
            body.append(compare_section(runs[0], runs[1], resamples) if common else
                        '<h2 id="compare">Comparison</h2><p class="note">The first two runs '
                        "share no scored sequence: nothing to compare.</p>")
        except DifferentData as exc:
            body.append(f'<h2 id="compare">Comparison</h2><p class="note">Not compared: '
                        f"{esc(str(exc))}</p>")
    body.append('<h2 id="events">Error events</h2><p>Each sequence\'s title opens its page: '
                'timeline, pictures and the list of its events.</p>' + legend())
    for i, (label, run, bench, metrics) in enumerate(loaded):
        names = list(metrics.get("per_sequence", {}))
        events = load_events(run) if names else pd.DataFrame(columns=["sequence", "frame",
                                                                       "type"])
        for seq in names:
            body.append(sequence_section(i, label, run, bench, seq,
                                         events[events["sequence"] == seq], out, thumbnails))
    return _write(out, "unitrack report", body)


#: What an ``index.html`` of ours holds near its top (pages before it: their title).
OURS = ("<meta name=\"generator\" content=\"unitrack-env\">", "<title>unitrack ")


def check_report_folder(out: Path) -> None:
    """Refuse a report folder whose page or radar chart a report of ours did not write."""
    index = out / "index.html"
    for path in (index, out / "scorecard.svg", out / "scorecard.png"):
        refuse_link(path)
    head = index.read_text(encoding="utf-8", errors="replace")[:4000] if index.is_file() else ""
    written = [index, out / "scorecard.svg", out / "scorecard.png",  # and the pages' files:
               *sorted(out.glob("seq*-*.html")), *sorted(out.glob("img*-*")),
               *sorted(out.glob("curves-*")), *sorted(out.glob("attributes-radar.*"))]
    theirs = [p.name for p in written if p.exists() and not any(mark in head for mark in OURS)]
    if theirs:
        raise FileExistsError(f"{out} holds {', '.join(theirs)}, which no report of ours wrote "
                              "(the report would replace it); it is kept: choose another "
                              "--out, or move it away")


def _write(out: Path, title: str, body: list[str]) -> Path:
    index = out / "index.html"
    atomic_write_text(index, page(title, body))  # a new file renamed in place, never via a link
    return index


__all__ = ["build_report"]
