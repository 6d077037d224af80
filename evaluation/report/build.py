"""Build the static HTML report of run folders (``unitrack report``), without replaying agents.

``index.html`` holds the sortable metrics table, the paired comparison of the first two runs,
and per run and sequence an event timeline with thumbnails of ID switches and bursts of
misses (linked to the frame and to a ``unitrack render`` clip when one is in the run folder).
A scorecard folder gives its table and radar chart.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from typing import Any

import pandas as pd

from ..compare import COMPARE_TASKS
from ..events import load_events, run_benchmark
from .html import esc, forest, mot_timeline, number_cell, page, table, value_timeline
from .thumbs import GT_COLOUR, PREVIOUS_COLOUR, TRACK_COLOUR, miss_bursts, render_picture, sample

#: Count metrics (shown as integers, not percent).
COUNTS = {"IDSW", "CLR_FP", "CLR_FN", "MT", "ML", "Frag", "IDs", "CLR_TP"}

#: Per-frame value shown on the timeline of a non-MOT task.
VALUE_COLUMNS = {"sot": ("iou", "IoU"), "vos": ("j", "J"), "pose-prop": ("pck", "PCK@0.1"),
                 "vis": ("iou", "IoU of tp tracks")}

#: Event lanes of the timeline of tasks with counted events, and what a count is; their
#: thumbnails are not drawn yet (masks, poses), only box MOT's.
LANES = {"mots": (None, "masks"), "posetrack": (("fn", "fp", "idsw"), "joints"),
         "vis": (("fn", "fp"), "track-frames")}


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", text).strip("-") or "x"


def _rgb(colour: tuple[int, int, int]) -> str:
    return "rgb({},{},{})".format(*colour)


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


def compare_section(run_a: Path, run_b: Path, resamples: int) -> str:
    """The paired comparison of two runs (box MOT, SOT, VOS, JHMDB) with 95% intervals."""
    from ..compare import compare_runs

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


def _mot_pictures(run: Path, bench: Any, seq: str, events: pd.DataFrame, out: Path,
                  folder: str, limit: int) -> list[str]:
    from unitrack_env.datasets.motchallenge import read_seqinfo

    info = read_seqinfo(bench.dataset.split_dir / seq)
    clip = _clip(run, seq)
    by_frame = {int(f): g for f, g in events.groupby("frame")}
    items = []
    for row in sample(list(events[events["type"] == "idsw"].itertuples()), limit):
        items.append(("idsw", int(row.frame), int(row.gt_id), int(row.track_id),
                      int(row.prev_track_id),
                      f"switch, frame {int(row.frame)}: gt {int(row.gt_id)} "
                      f"track {int(row.prev_track_id)} → {int(row.track_id)}"))
    bursts = miss_bursts(events[events["type"] == "fn"])
    for gt_id, start, length in sample(sorted(bursts, key=lambda b: (b[1], b[0])), limit):
        items.append(("miss", start, gt_id, None, None,
                      f"miss, frames {start}-{start + length - 1}: gt {gt_id}"))
    figures = []
    for kind, frame, gt_id, track, prev, caption in items:
        path = info.frame_path(frame)
        if not path.is_file():
            continue
        name = f"{kind}-f{frame:06d}-g{gt_id}"
        thumb, full = render_picture(path, by_frame.get(frame, events.iloc[:0]), out / folder,
                                     name, gt_id=gt_id, track_id=track, prev_track_id=prev)
        link = ""
        if clip is not None:
            t = (frame - 1) / max(1.0, float(info.frame_rate))
            link = f' · <a href="{esc(clip.resolve().as_uri())}#t={t:.2f}">clip</a>'
        figures.append(f'<figure><a href="{esc(full)}"><img loading="lazy" class="thumb '
                       f'{kind}" data-kind="{kind}" data-frame="{frame}" src="{esc(thumb)}" '
                       f'alt="{esc(caption)}"></a><figcaption>{esc(caption)}{link}'
                       "</figcaption></figure>")
    return figures


def sequence_section(index: int, label: str, run: Path, bench: Any, seq: str,
                     events: pd.DataFrame, out: Path, limit: int) -> str:
    """A run's sequence: its event timeline and (MOT) event thumbnails."""
    frames = bench.sequence_length(seq)
    head = f'<h3 id="{_slug(label)}-{_slug(seq)}">{esc(label)} · {esc(seq)} ({frames} frames)</h3>'
    if bench.task == "mot":
        figures = _mot_pictures(run, bench, seq, events, out, f"img{index}-{_slug(seq)}", limit)
        shown = (f"<p>{len(figures)} pictures (at most {limit} ID switches and {limit} bursts "
                 "of misses, sampled evenly over the sequence).</p>") if figures else \
            "<p>No ID switch or miss to picture (or the frames are not on this machine).</p>"
        return (f'<section class="sequence" data-sequence="{esc(seq)}">{head}'
                + mot_timeline(events, frames) + shown
                + '<div class="thumbs">' + "".join(figures) + "</div></section>")
    body = ""
    if bench.task in LANES:
        kinds, unit = LANES[bench.task]
        body = (mot_timeline(events, frames, kinds=kinds) + f"<p>Counts are {unit}; no "
                "thumbnails for this task yet (only box MOT's are drawn).</p>")
    column, name = VALUE_COLUMNS.get(bench.task, (None, None))
    if column is not None and column in events:
        rows = events[events["type"] == "tp"] if bench.task == "vis" else events
        body += value_timeline(rows[column], rows["frame"], name, frames)
    body = body or "<p>No per-frame events.</p>"
    return f'<section class="sequence" data-sequence="{esc(seq)}">{head}{body}</section>'


def scorecard_section(folder: Path, out: Path) -> str:
    """A scorecard folder's table (its Markdown as HTML) and radar chart."""
    from ..correlation_plot import report_section as correlation_section
    from ..scorecard_report import columns, value

    card = json.loads((folder / "scorecard.json").read_text(encoding="utf-8"))
    cols = columns(card)
    from ..scorecard_plan import BASELINE

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
            shutil.copyfile(src, out / src.name)
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


def _legend() -> str:
    return ('<p class="legend">Boxes:<span style="background:' + _rgb(GT_COLOUR)
            + '"></span>ground truth<span style="background:' + _rgb(TRACK_COLOUR)
            + '"></span>track matched at the event<span style="background:'
            + _rgb(PREVIOUS_COLOUR) + '"></span>track matched before the switch</p>')


def build_report(runs: list[Path], out: Path, *, thumbnails: int = 24,
                 resamples: int = 500) -> Path:
    """Write ``out/index.html`` for run folders (or one scorecard folder); return its path."""
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
        loaded.append((label, run, run_benchmark(run),
                       json.loads(metrics_path.read_text(encoding="utf-8"))))
    body = [f"<h1>unitrack report: {esc(', '.join(r.name for r in runs))}</h1>",
            "<p>" + esc(", ".join(f"{lab}: {b.name}" for lab, _, b, _ in loaded)) + "</p>",
            metrics_section(loaded)]
    if len(loaded) >= 2 and loaded[0][2].task == loaded[1][2].task in COMPARE_TASKS:
        common = set(loaded[0][3]["per_sequence"]) & set(loaded[1][3]["per_sequence"])
        body.append(compare_section(runs[0], runs[1], resamples) if common else
                    '<h2 id="compare">Comparison</h2><p class="note">The first two runs share '
                    "no scored sequence: nothing to compare.</p>")
    body.append('<h2 id="events">Error events</h2>' + _legend())
    for i, (label, run, bench, metrics) in enumerate(loaded):
        names = list(metrics.get("per_sequence", {}))
        events = load_events(run) if names else pd.DataFrame(columns=["sequence", "frame",
                                                                       "type"])
        for seq in names:
            body.append(sequence_section(i, label, run, bench, seq,
                                         events[events["sequence"] == seq], out, thumbnails))
    return _write(out, "unitrack report", body)


def _write(out: Path, title: str, body: list[str]) -> Path:
    index = out / "index.html"
    tmp = index.with_suffix(".html.tmp")
    tmp.write_text(page(title, body), encoding="utf-8")
    tmp.replace(index)
    return index


__all__ = ["build_report"]
