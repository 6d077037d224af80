"""``unitrack report``: a self-contained HTML report of runs or of a scorecard folder."""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from .common import positive_int

EXAMPLES = """examples:
  unitrack report runs/pets-unitrack --out report/
  unitrack report runs/pets-unitrack runs/pets-iou --out report/   # with the comparison
  unitrack report runs/scorecard --out report/                      # a scorecard folder
"""


def add_arguments(rp: argparse.ArgumentParser) -> None:
    """The options of ``unitrack report``."""
    rp.add_argument("runs", nargs="+", metavar="RUN",
                    help="run folders (the first two are compared) or a scorecard folder")
    rp.add_argument("--out", required=True, help="report folder (index.html and images)")
    rp.add_argument("--thumbnails", type=positive_int, default=24,
                    help="at most this many thumbnails per sequence and kind (default: 24)")
    rp.add_argument("--resamples", type=positive_int, default=500,
                    help="bootstrap resamples of the comparison (default: 500)")


def run(args: argparse.Namespace, console: Console) -> int:
    """Run ``unitrack report``."""
    # lazy: start-up cost (pandas, scipy, TrackEval: `unitrack report --help` 0.24 s, else 1.63 s)
    from ..report.build import build_report

    index = build_report([Path(r) for r in args.runs], Path(args.out),
                         thumbnails=args.thumbnails, resamples=args.resamples)
    console.print(f"report: {index}", markup=False)
    return 0
