"""``unitrack compare``: two runs, their paired difference and its 95% interval."""

from __future__ import annotations

import argparse
import json
from typing import Any

from rich.console import Console

from .common import positive_int

EXAMPLES = """examples:
  unitrack compare runs/pets-unitrack runs/pets-iou
  unitrack compare runs/a runs/b --resamples 2000 --format json
"""


def add_arguments(cp: argparse.ArgumentParser) -> None:
    """The options of ``unitrack compare``."""
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


def comparison_lines(comp: Any) -> list[str]:
    """A plain-text table of a :class:`~.compare.Comparison`, in percent points."""
    width = max([6, *(len(m) for row in comp.rows.values() for m in row)])  # car/HOTA too
    lines = [f"A = {comp.run_a}", f"B = {comp.run_b}",
             (f"paired block jackknife ({comp.level})" if comp.method == "jackknife" else
              f"paired block bootstrap ({comp.level}), {comp.resamples} resamples")
             + "; 95% interval of A - B",
             f"{'sequence':<18} {'metric':<{width}} {'A':>7} {'B':>7} {'A-B':>7} "
             f"{'95% interval':>17}  frames"]
    for name, row in comp.rows.items():
        frames = comp.frames.get(name, sum(comp.frames.values()))
        for metric, d in row.items():
            star = " *" if d.significant else "" if d.reliable else " (too little data)"
            lines.append(f"{name:<18} {metric:<{width}} {100 * d.a:7.1f} {100 * d.b:7.1f} "
                         f"{100 * d.diff:+7.1f} [{100 * d.low:+6.1f}, {100 * d.high:+6.1f}]"
                         f"  {frames}{star}")
    lines.append("* the interval excludes 0 (and rests on enough frames to say so)")
    lines += [f"note: {n}" for n in comp.notes]
    return lines


def run(args: argparse.Namespace, console: Console) -> int:
    """Run ``unitrack compare``."""
    # lazy: start-up cost (pandas, scipy: `unitrack compare --help` 0.24 s, else 1.45 s)
    from ..analysis.intervals import compare_runs

    comp = compare_runs(args.runs[0], args.runs[1], resamples=args.resamples, seed=args.seed,
                        level=args.level, block=args.block, method=args.interval)
    if args.format == "json":
        print(json.dumps(comp.to_json(), indent=2))
    else:
        for line in comparison_lines(comp):
            console.print(line, markup=False)
    return 0
