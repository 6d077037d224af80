"""The ``unitrack plot`` command: success and precision plots of SOT run folders."""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

EXAMPLES = """examples:
  unitrack plot runs/otb-xcorr --out plots/
  unitrack plot runs/lasot-xcorr runs/lasot-repeat --out plots/   # both runs on each figure
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``unitrack plot``."""
    parser.add_argument("runs", nargs="+", metavar="RUN", help="run folders of `unitrack "
                        "evaluate` (scored)")
    parser.add_argument("--out", required=True, help="folder of the figures "
                        "(success-plot.png/.svg, precision-plot.png/.svg, ...)")


def run(args: argparse.Namespace, console: Console) -> int:
    """Run ``unitrack plot``."""
    from ..curves_plot import draw_curves

    written = draw_curves([Path(r) for r in args.runs], Path(args.out))
    for path in written:
        console.print(str(path), markup=False)
    return 0 if written else 1
