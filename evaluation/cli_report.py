"""The ``unitrack events``, ``unitrack compare`` and ``unitrack report`` commands."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from rich.console import Console

from .cli_types import positive_int

EXAMPLES = {
    "events": """examples:
  unitrack events runs/pets --type idsw
  unitrack events runs/pets --sequence PETS09-S2L1 --type fn --format csv > misses.csv
""",
    "compare": """examples:
  unitrack compare runs/pets-unitrack runs/pets-iou
  unitrack compare runs/a runs/b --resamples 2000 --format json
""",
    "report": """examples:
  unitrack report runs/pets-unitrack --out report/
  unitrack report runs/pets-unitrack runs/pets-iou --out report/   # with the comparison
  unitrack report runs/scorecard --out report/                      # a scorecard folder
""",
}

#: Columns ``unitrack events`` prints as a table (``--format csv`` prints them all).
TABLE_COLUMNS = ("sequence", "frame", "type", "object", "gt_id", "track_id", "prev_track_id",
                 "joint", "iou", "center_error", "j", "f", "pck", "distance", "score",
                 "track_iou")


def add_parsers(sub: Any) -> None:
    """Register ``events``, ``compare`` and ``report`` on the ``unitrack`` subparsers."""
    def command(name: str, help_text: str) -> argparse.ArgumentParser:
        # help (in `unitrack --help`) is %-formatted by argparse, the description is not
        return sub.add_parser(name, help=help_text, description=help_text.replace("%%", "%"),
                              epilog=EXAMPLES[name],
                              formatter_class=argparse.RawDescriptionHelpFormatter)

    ev = command("events", "list a run's per-frame error events (ID switches, misses, false "
                 "positives, ...; computed from its result files if the run predates them)")
    ev.add_argument("run", help="a run folder of `unitrack evaluate`")
    ev.add_argument("--sequence", help="only this sequence")
    ev.add_argument("--type", help="only this event type: tp, fp, fn, idsw, frag (MOT, MOTS; "
                    "PoseTrack per joint), tp, fp, fn, ignored (VIS, per track and frame) or "
                    "frame (SOT, VOS, JHMDB)")
    ev.add_argument("--format", choices=("table", "csv", "count"), default="table",
                    help="a table, every column as CSV, or the count per sequence and type")
    ev.set_defaults(func=_cmd_events)

    cp = command("compare", "compare two runs: per-sequence and combined metrics, the paired "
                 "difference and its 95%% interval (paired block jackknife)")
    cp.add_argument("runs", nargs=2, metavar="RUN", help="two run folders (A, then B)")
    cp.add_argument("--resamples", type=positive_int, default=1000,
                    help="bootstrap resamples of --interval percentile|bc|basic "
                    "(default: 1000)")
    cp.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    cp.add_argument("--interval", choices=("jackknife", "percentile", "bc", "basic"),
                    default="jackknife", help="jackknife (default; its coverage is measured "
                    "in docs/report.md) or a block bootstrap interval")
    cp.add_argument("--level", choices=("frames", "sequences"), default="frames",
                    help="leave out frame blocks within each sequence (default) or whole "
                    "sequences (needs many sequences)")
    cp.add_argument("--block", type=positive_int,
                    help="block length in frames (default: a fifth of the sequence)")
    cp.add_argument("--format", choices=("table", "json"), default="table",
                    help="a table in percent (default) or every number as JSON")
    cp.set_defaults(func=_cmd_compare)

    rp = command("report", "write a self-contained HTML report of runs (or a scorecard "
                 "folder): metrics, error timelines, thumbnails of ID switches and misses")
    rp.add_argument("runs", nargs="+", metavar="RUN",
                    help="run folders (the first two are compared) or a scorecard folder")
    rp.add_argument("--out", required=True, help="report folder (index.html and images)")
    rp.add_argument("--thumbnails", type=positive_int, default=24,
                    help="at most this many thumbnails per sequence and kind (default: 24)")
    rp.add_argument("--resamples", type=positive_int, default=500,
                    help="bootstrap resamples of the comparison (default: 500)")
    rp.set_defaults(func=_cmd_report)


def _cmd_events(args: argparse.Namespace, console: Console) -> int:
    from .events import event_counts, load_events

    df = load_events(args.run, sequence=args.sequence, type=args.type)
    if args.format == "csv":
        print(df.to_csv(index=False, float_format="%.4f"), end="")
        return 0
    if args.format == "count":
        console.print(json.dumps(event_counts(df), indent=2), markup=False)
        return 0
    from rich.table import Table

    if args.type is None:  # thousands of lines help nobody: the counts, and how to list
        _events_summary(console, event_counts(df), len(df))
        return 0

    cols = [c for c in TABLE_COLUMNS if c in df and df[c].notna().any()]
    table = Table(*cols, title=f"{len(df)} events")
    for row in df[cols].itertuples(index=False):
        table.add_row(*("" if _missing(v) else f"{v:.3f}" if isinstance(v, float) else str(v)
                        for v in row))
    console.print(table)
    return 0


def _events_summary(console: Console, counts: dict[str, dict[str, int]], total: int) -> None:
    from rich.table import Table

    kinds = list(dict.fromkeys(kind for row in counts.values() for kind in row))
    table = Table("sequence", title=f"{total} events", title_justify="left")
    for kind in kinds:
        table.add_column(kind, justify="right")
    for sequence, row in counts.items():
        table.add_row(sequence, *(str(row.get(kind, 0)) for kind in kinds))
    console.print(table)
    example = next((k for k in ("idsw", "fn", "frame") if k in kinds), kinds[0] if kinds else "")
    console.print(f"--type TYPE lists the events of one type (e.g. --type {example}); "
                  "--format csv lists every event with every column", markup=False)


def _missing(value: Any) -> bool:
    try:
        return bool(value != value) or value is None or str(value) == "<NA>"
    except (TypeError, ValueError):
        return True


def comparison_lines(comp: Any) -> list[str]:
    """A plain-text table of a :class:`~.compare.Comparison`, in percent points."""
    lines = [f"A = {comp.run_a}", f"B = {comp.run_b}",
             (f"paired block jackknife ({comp.level})" if comp.method == "jackknife" else
              f"paired block bootstrap ({comp.level}), {comp.resamples} resamples")
             + "; 95% interval of A - B",
             f"{'sequence':<18} {'metric':<6} {'A':>7} {'B':>7} {'A-B':>7} "
             f"{'95% interval':>17}  frames"]
    for name, row in comp.rows.items():
        frames = comp.frames.get(name, sum(comp.frames.values()))
        for metric, d in row.items():
            star = " *" if d.significant else "" if d.reliable else " (too little data)"
            lines.append(f"{name:<18} {metric:<6} {100 * d.a:7.1f} {100 * d.b:7.1f} "
                         f"{100 * d.diff:+7.1f} [{100 * d.low:+6.1f}, {100 * d.high:+6.1f}]"
                         f"  {frames}{star}")
    lines.append("* the interval excludes 0 (and rests on enough frames to say so)")
    lines += [f"note: {n}" for n in comp.notes]
    return lines


def _cmd_compare(args: argparse.Namespace, console: Console) -> int:
    from .intervals import compare_runs

    comp = compare_runs(args.runs[0], args.runs[1], resamples=args.resamples, seed=args.seed,
                        level=args.level, block=args.block, method=args.interval)
    if args.format == "json":
        print(json.dumps(comp.to_json(), indent=2))
    else:
        for line in comparison_lines(comp):
            console.print(line, markup=False)
    return 0


def _cmd_report(args: argparse.Namespace, console: Console) -> int:
    from .report.build import build_report

    index = build_report([Path(r) for r in args.runs], Path(args.out),
                         thumbnails=args.thumbnails, resamples=args.resamples)
    console.print(f"report: {index}", markup=False)
    return 0
