"""The ``unitrack plot`` command: success and precision plots of SOT run folders."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from rich.console import Console

EXAMPLES = """examples:
  unitrack plot runs/otb-xcorr --out plots/
  unitrack plot runs/lasot-xcorr runs/lasot-repeat --out plots/   # both runs on each figure
"""


def add_parser(sub: Any) -> None:
    """Register ``plot`` on the ``unitrack`` subparsers."""
    text = ("draw the success and precision plots (and normalized precision where the "
            "benchmark has it) of SOT runs, all runs on one figure, as PNG and SVG")
    parser = sub.add_parser("plot", help=text, description=text, epilog=EXAMPLES,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", metavar="RUN", help="run folders of `unitrack "
                        "evaluate` (scored)")
    parser.add_argument("--out", required=True, help="folder of the figures "
                        "(success-plot.png/.svg, precision-plot.png/.svg, ...)")
    parser.set_defaults(func=_cmd_plot)


def _cmd_plot(args: argparse.Namespace, console: Console) -> int:
    from .curves_plot import draw_curves

    written = draw_curves([Path(r) for r in args.runs], Path(args.out))
    for path in written:
        console.print(str(path), markup=False)
    return 0 if written else 1
