"""The ``unitrack scorecard`` command: its options, its progress bar over cells, and its run."""

from __future__ import annotations

import argparse
import contextlib
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from rich.console import Console

from unitrack_env.evaluation.cli_types import positive_int


def add_options(card: argparse.ArgumentParser) -> None:
    """The options of ``unitrack scorecard``."""
    card.add_argument("--model", action="append",
                      metavar="WEIGHTS[,arch=A][,layer=L][,stride=S][,label=N]",
                      help="an appearance model (a row): imagenet-lite0, random, or a "
                      "checkpoint file, with options (repeatable)")
    card.add_argument("--data", help="folder holding benchmark folders (MOT17/, DAVIS/, ...; "
                      "default: $UNITRACK_DATA); tasks without one use synthetic data, marked")
    card.add_argument("--tasks", help="comma-separated subset of: sot, vos, mot, mots, "
                      "posetrack, pose-prop, vis (default: all)")
    card.add_argument("--out", required=True, help="output folder (finished cells are reused)")
    card.add_argument("--backend", choices=("pool", "ray"), default="pool",
                      help="where cells run: local processes (default) or Ray")
    card.add_argument("--workers", type=positive_int, default=1,
                      help="pool processes, or the CPUs of a local Ray (default: 1)")
    card.add_argument("--address", help="Ray cluster to join: auto or ray://host:port "
                      "(default: start a local Ray)")
    card.add_argument("--motion", action="store_true", help="keep motion cues in the "
                      "association heads (the paper's Table 2 drops them)")
    card.add_argument("--runtime", choices=("torch", "openvino", "onnxruntime", "auto"),
                      help="inference runtime of the appearance models: auto picks the "
                      "fastest installed (default: $UNITRACK_RUNTIME, else torch)")
    card.add_argument("--radar-scale", choices=("rank", "value"), default="rank",
                      help="radar axes: rank among the models (the paper's) or the value")
    card.add_argument("--compare", nargs="+", metavar="SCORECARD_JSON",
                      help="redraw earlier scorecard.json files together (plays nothing)")
    card.add_argument("--quiet", action="store_true", help="no progress bar")
    card.set_defaults(func=run_command)


def run_command(args: argparse.Namespace, console: Console) -> int:
    """Run ``unitrack scorecard`` (or redraw earlier cards with ``--compare``)."""
    from unitrack_env.evaluation import scorecard as sc
    from unitrack_env.evaluation.scorecard_report import merge_cards

    out = Path(args.out)
    if args.compare:
        card = merge_cards([Path(p) for p in args.compare])
        files = sc.write_outputs(out, card, radar_scale=args.radar_scale)
    else:
        if not args.model:
            raise ValueError("give --model (one or more), or --compare earlier scorecards")
        models = [sc.ModelSpec.parse(text) for text in args.model]
        tasks = args.tasks.split(",") if args.tasks else None
        data = args.data or os.environ.get("UNITRACK_DATA")
        with cell_progress(enabled=not args.quiet) as progress:
            card = sc.scorecard(models, out=out, tasks=tasks, data=data, backend=args.backend,
                                workers=args.workers, address=args.address,
                                motion=args.motion, runtime=args.runtime,
                                radar_scale=args.radar_scale,
                                on_progress=progress)
        files = sorted(out.glob("scorecard.*"))
    console.print((out / "scorecard.md").read_text(), markup=False, soft_wrap=True)
    console.print("wrote " + ", ".join(str(f) for f in files), markup=False, soft_wrap=True)
    return 0


@contextlib.contextmanager
def cell_progress(enabled: bool) -> Iterator[Callable[[int, int, Any], None]]:
    """A progress bar over scorecard cells: done / all, ETA, the cell that just finished."""
    if not enabled:
        yield lambda done, total, cell: None
        return
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )
    from rich.table import Column

    with Progress(TextColumn("cells"), BarColumn(bar_width=20), MofNCompleteColumn(),
                  TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
                  TextColumn("{task.description}",
                             table_column=Column(no_wrap=True, overflow="ellipsis")),
                  console=Console(stderr=True, highlight=False, soft_wrap=True)) as progress:
        task = progress.add_task("", total=None)

        def update(done: int, total: int, cell: Any) -> None:
            progress.update(task, completed=done, total=total,
                            description="" if cell is None else cell.label[-48:])

        yield update
