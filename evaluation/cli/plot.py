"""The ``unitrack plot`` command: success and precision plots of SOT run folders."""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

EXAMPLES = """examples:
  unitrack plot runs/otb-xcorr --out plots/
  unitrack plot runs/lasot-xcorr runs/lasot-repeat --out plots/   # both runs on each figure
  unitrack plot runs/otb-xcorr runs/otb-dcf --out plots/ --attributes   # + per-attribute table
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``unitrack plot``."""
    parser.add_argument("runs", nargs="+", metavar="RUN", help="run folders of `unitrack "
                        "evaluate` (scored)")
    parser.add_argument("--out", required=True, help="folder of the figures "
                        "(success-plot.png/.svg, precision-plot.png/.svg, ...)")
    parser.add_argument("--attributes", action="store_true", help="also score each "
                        "challenge attribute of the benchmark (OTB-2015, LaSOT, UAV123) over "
                        "the sequences having it: attributes.md/.csv and the radar "
                        "attributes-radar.png/.svg")


def run(args: argparse.Namespace, console: Console) -> int:
    """Run ``unitrack plot``."""
    # lazy: start-up cost (pandas, TrackEval: `unitrack plot --help` 0.25 s, else 1.05 s)
    from ..plots.attributes import load_attributes, write_attributes
    from ..plots.curves import draw_curves

    runs = [Path(r) for r in args.runs]
    if args.attributes:  # read (and refused if bad) before any figure is written
        tables, without = load_attributes(runs)
    written = draw_curves(runs, Path(args.out))
    if args.attributes:
        files, table = write_attributes(tables, without, Path(args.out))
        console.print(table, markup=False)
        written += files
    for path in written:
        console.print(str(path), markup=False)
    return 0 if written else 1
