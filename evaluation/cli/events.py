"""``unitrack events``: a run's per-frame error events (ID switches, misses, ...)."""

from __future__ import annotations

import argparse
import json
from typing import Any

from rich.console import Console
from rich.table import Table

EXAMPLES = """examples:
  unitrack events runs/pets --type idsw
  unitrack events runs/pets --sequence PETS09-S2L1 --type fn --format csv > misses.csv
"""


def add_arguments(ev: argparse.ArgumentParser) -> None:
    """The options of ``unitrack events``."""
    ev.add_argument("run", help="a run folder of `unitrack evaluate`")
    ev.add_argument("--sequence", help="only this sequence")
    ev.add_argument("--type", help="only this event type: tp, fp, fn, idsw, frag (MOT, MOTS; "
                    "PoseTrack per joint), tp, fp, fn, ignored (VIS, per track and frame) or "
                    "frame (SOT, VOS, JHMDB)")
    ev.add_argument("--format", choices=("table", "csv", "count"), default="table",
                    help="a table, every column as CSV, or the count per sequence and type")


#: Columns ``unitrack events`` prints as a table (``--format csv`` prints them all).
TABLE_COLUMNS = ("sequence", "frame", "type", "class", "object", "gt_id", "track_id",
                 "prev_track_id", "joint", "iou", "center_error", "j", "f", "pck", "distance",
                 "score", "track_iou")


def run(args: argparse.Namespace, console: Console) -> int:
    """Run ``unitrack events``."""
    # lazy: start-up cost (pandas, TrackEval: `unitrack events --help` 0.25 s, else 1.13 s)
    from ..analysis.events import event_counts, load_events

    df = load_events(args.run, sequence=args.sequence, type=args.type)
    if args.format == "csv":
        print(df.to_csv(index=False, float_format="%.4f"), end="")
        return 0
    if args.format == "count":
        console.print(json.dumps(event_counts(df), indent=2), markup=False)
        return 0
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
