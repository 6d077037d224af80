"""The ``unitrack scorecard`` command: its options, its progress bar over cells, and its run."""

from __future__ import annotations

import argparse
import contextlib
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    TextColumn,
    TimeElapsedColumn,
)
from rich.table import Column
from rich.text import Text

from .common import positive_int


def add_arguments(card: argparse.ArgumentParser) -> None:
    """The options of ``unitrack scorecard``."""
    card.add_argument("--model", action="append",
                      metavar="WEIGHTS[,arch=A][,layer=L][,stride=S][,label=N][,KIND:NAME=V]",
                      help="an appearance model (a row): imagenet-lite0, random, or a "
                      "checkpoint file, with options and numbers from other evaluations, "
                      "e.g. probe:imagenet=71.1 (repeatable)")
    card.add_argument("--external", metavar="CSV", help="numbers from other evaluations: "
                      "a CSV with a model column (the labels) and KIND:NAME[:lower] columns; "
                      "writes the correlation study (correlation.md/.json and figures)")
    card.add_argument("--data", help="folder holding benchmark folders (MOT17/, DAVIS/, ...; "
                      "default: $UNITRACK_DATA); tasks without one use synthetic data, marked")
    card.add_argument("--tasks", help="comma-separated subset of: sot, vos, mot, mots, "
                      "posetrack, pose-prop, vis (default: all of these), or an opt-in "
                      "column named on its own (points: TAP-Vid; sot-lasot, sot-got10k: "
                      "SOT on LaSOT, GOT-10k val; dancetrack: MOT on DanceTrack)")
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
                      "fastest installed, checked against torch per model and input size "
                      "(default: $UNITRACK_RUNTIME, else auto)")
    card.add_argument("--radar-scale", choices=("rank", "value"), default="rank",
                      help="radar axes: rank among the models (the paper's) or the value")
    card.add_argument("--compare", nargs="+", metavar="SCORECARD_JSON",
                      help="redraw earlier scorecard.json files together (plays nothing)")
    card.add_argument("--restamp", action="store_true",
                      help="keep stored cells whose only change is the agent's code (you vouch "
                      "the edit cannot change them); each is checked and the changed files "
                      "are printed")
    card.add_argument("--quiet", action="store_true", help="no progress bar")
    card.add_argument("--ci", action="store_true", help="also write each cell's 95%% bootstrap "
                      "interval (scorecard_ci.md/.json; see docs/report.md)")


def _print_restamp(console: Console, label: str, result: list[str] | str) -> None:
    if isinstance(result, str):
        console.print(f"not re-stamped {label}: {result}; it is played again", markup=False,
                      soft_wrap=True)
    else:
        console.print(f"re-stamped {label}: kept across your edit of {', '.join(result)}",
                      markup=False, soft_wrap=True)


def run(args: argparse.Namespace, console: Console) -> int:
    """Run ``unitrack scorecard`` (or redraw earlier cards with ``--compare``)."""
    # lazy: start-up cost (scipy, TrackEval: `unitrack scorecard --help` 0.23 s, else 1.50 s)
    from ..scorecard import card as sc
    from ..scorecard.correlation_study import (
        merge_externals,
        read_external_csv,
        split_model_text,
        write_correlation,
    )
    from ..scorecard.intervals import write_card_intervals
    from ..scorecard.plan import ModelSpec
    from ..scorecard.table import merge_cards

    out = Path(args.out)
    split = [split_model_text(text) for text in args.model or ()]
    externals = read_external_csv(args.external) if args.external else {}
    if args.compare:
        card = merge_cards([Path(p) for p in args.compare])
        files = sc.write_outputs(out, card, radar_scale=args.radar_scale)
    else:
        if not args.model:
            raise ValueError("give --model (one or more), or --compare earlier scorecards")
        models = [ModelSpec.parse(text) for text, _ in split]
        externals = merge_externals(externals, *({m.name: given} for m, (_, given)
                                                 in zip(models, split, strict=True)))
        tasks = args.tasks.split(",") if args.tasks else None
        data = args.data or os.environ.get("UNITRACK_DATA")
        with cell_progress(enabled=not args.quiet) as progress:
            card = sc.scorecard(models, out=out, tasks=tasks, data=data, backend=args.backend,
                                workers=args.workers, address=args.address,
                                motion=args.motion, runtime=args.runtime,
                                radar_scale=args.radar_scale,
                                on_progress=progress,
                                on_estimate=None if args.quiet else progress.estimate,
                                restamp=args.restamp,
                                on_restamp=lambda label, result: _print_restamp(
                                    console, label, result))
        files = sorted(out.glob("scorecard.*"))
    if args.ci:
        files += write_card_intervals(out, card)
    if any(externals.values()):
        files += write_correlation(out, card, externals)
    console.print((out / "scorecard.md").read_text(), markup=False, soft_wrap=True)
    if any(externals.values()):
        console.print((out / "correlation.md").read_text(), markup=False, soft_wrap=True)
    console.print("wrote " + ", ".join(str(f) for f in files), markup=False, soft_wrap=True)
    return 0


class _Update:
    """The scorecard's callbacks into the bar.

    ``update(done, total, cell)`` per cell; ``update.estimate(seconds_left)`` whenever the
    scorecard recomputes its ETA.
    """

    def __init__(self, progress: Any = None, task: Any = None) -> None:
        self.progress, self.task = progress, task

    def __call__(self, done: int, total: int, cell: Any) -> None:
        if self.progress is not None:
            self.progress.update(self.task, completed=done, total=total,
                                 description="" if cell is None else cell.label[-48:])

    def estimate(self, seconds: float) -> None:
        if self.progress is not None:
            self.progress.update(self.task, eta=(time.monotonic(), seconds))


class _EtaColumn(ProgressColumn):
    """The scorecard's own ETA, counting down between cells.

    From the cells' frames and input sizes, corrected as they finish; rich's own column
    would wait for two finished cells. Drawn at every refresh (a countdown in whole
    seconds does not flicker), so a new estimate shows at once.
    """

    max_refresh = None

    def render(self, task: Any) -> Text:
        stamp, seconds = task.fields.get("eta", (None, None))
        if stamp is None or task.finished:  # before the plan: models and data load
            return Text("-:--:--" if task.finished else "planning",
                        style="progress.remaining")
        left = max(0, round(seconds - (time.monotonic() - stamp)))
        return Text(f"{left // 3600}:{left // 60 % 60:02d}:{left % 60:02d}",
                    style="progress.remaining")


@contextlib.contextmanager
def cell_progress(enabled: bool) -> Iterator[_Update]:
    """A progress bar over scorecard cells: done / all, ETA, the cell that just finished."""
    if not enabled:
        yield _Update()
        return
    with Progress(TextColumn("cells"), BarColumn(bar_width=20), MofNCompleteColumn(),
                  TimeElapsedColumn(), TextColumn("ETA"), _EtaColumn(),
                  TextColumn("{task.description}",
                             table_column=Column(no_wrap=True, overflow="ellipsis")),
                  console=Console(stderr=True, highlight=False, soft_wrap=True)) as progress:
        yield _Update(progress, progress.add_task("", total=None))
