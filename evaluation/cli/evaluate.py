"""``unitrack evaluate``: run an agent on every sequence of an environment and score it."""

from __future__ import annotations

import argparse
import contextlib
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from unitrack_env.agents.base import agent_class
from unitrack_env.agents.options import agent_options
from unitrack_env.benchmarks import benchmark_for

from ..analysis.tables import format_cell, table_columns
from ..run.watchdog import DEFAULT_STEP_TIMEOUT
from .cache import run_summary
from .common import (
    agent_kwargs,
    console,
    env_kwargs,
    env_options,
    format_option,
    names,
    non_negative_float,
    positive_int,
    print_metrics,
)

EXAMPLES = """examples:
  unitrack evaluate --env UniTrack/MOT16-v0 --agent iou --out runs/quickstart
  unitrack evaluate --env UniTrack/MOT17-v0 --root data/MOT17 --agent unitrack \\
      --agent-arg weights=moco_v2.pth --workers 2 --out runs/mot17
  unitrack evaluate --env UniTrack/MOT16-v0 --agent my_trackers:Nearest --out runs/mine
  unitrack evaluate --env UniTrack/OTB-v0 --agent trackers/sot.py:MySOT --out runs/sot
"""


def add_arguments(ev: argparse.ArgumentParser) -> None:
    """The options of ``unitrack evaluate``."""
    env_options(ev)
    ev.add_argument("--out", required=True, help="output folder: results in the official "
                    "format, per-sequence records, metrics.json (an existing run is resumed)")
    ev.add_argument("--sequences", type=names,
                    help="comma-separated sequence names (default: all)")
    ev.add_argument("--workers", type=positive_int, default=1,
                    help="parallel worker processes, one sequence each (default: 1)")
    ev.add_argument("--overwrite", action="store_true",
                    help="discard a previous run in --out instead of resuming it (deletes only "
                    "the files runs of ours wrote, listed in <out>/manifest.json)")
    ev.add_argument("--restamp", action="store_true",
                    help="keep finished sequences whose only change is the agent's code (you "
                    "vouch the edit cannot change them: a comment, a rename); each is checked, "
                    "and the changed files are printed")
    ev.add_argument("--step-timeout", type=non_negative_float, default=DEFAULT_STEP_TIMEOUT,
                    metavar="SECONDS", help="a step (the agent's act() and the env's step) "
                    "longer than this fails its sequence (default: %(default)g; 0: no limit)")
    ev.add_argument("--in-process", action="store_true", help="with --workers 1, play here "
                    "(for a debugger), not in a supervised child process that can be stopped")
    ev.add_argument("--backend", choices=("local", "ray"), default="local", help="where "
                    "sequences play: local processes (--workers) or Ray tasks, one each")
    ev.add_argument("--address", help="with --backend ray: the cluster to join, auto or "
                    "ray://host:port (default: start a local Ray with --workers CPUs)")
    ev.add_argument("--repeats", type=positive_int, default=1, metavar="K",
                    help="play each sequence K times in a row (GOT-10k's protocol asks for 3): "
                    "each repetition is written (GOT-10k: <seq>_00k.txt; others: "
                    "data/repeat-00k/) and the metrics' mean, min and max over them are "
                    "printed and stored in metrics.json (default: 1)")
    ev.add_argument("--quiet", action="store_true", help="no progress bar")
    format_option(ev)


def _defined(value: Any) -> bool:
    return value is not None and not (isinstance(value, float) and value != value)


@contextlib.contextmanager
def feature_cache_report(agent: str, agent_kwargs: dict[str, Any]) -> Iterator[
        Callable[[], str | None]]:
    """Count the feature-cache hits of a run, for agents that have a feature cache option.

    Yields a function that returns the summary once the run is over (None without a cache:
    other agents do not pay for importing the appearance stack). A run that stored features
    adds a line with the cache's folder, its size and how to trim it.
    """
    if "feature_cache" not in agent_options(agent_class(agent)):
        yield lambda: None
        return
    # lazy: start-up cost (the appearance package loads torch: +1.6 s for agents without it)
    from unitrack_env.agents.appearance.cache_runs import track_cache_run

    folder = agent_kwargs.get("feature_cache")
    root = Path(folder).expanduser() if isinstance(folder, (str, os.PathLike)) else None
    with track_cache_run(root) as cache_run:
        yield lambda: run_summary(cache_run, root)


def run(args: argparse.Namespace, out: Console) -> int:
    """Run ``unitrack evaluate``."""
    # lazy: start-up cost (scipy, TrackEval: `unitrack evaluate --help` 0.23 s, else 1.06 s)
    from ..run.runner import run as play

    env_given = env_kwargs(args)
    agent_given = agent_kwargs(args)
    with feature_cache_report(args.agent, agent_given) as cache_summary:
        report = play(args.env, args.agent, out=args.out, env_kwargs=env_given,
                      agent_kwargs=agent_given, sequences=args.sequences,
                      workers=args.workers, overwrite=args.overwrite, isolate=not args.in_process,
                      progress=not args.quiet and args.format == "table",
                      step_timeout=args.step_timeout, restamp=args.restamp,
                      backend=args.backend, address=args.address, repeats=args.repeats)
    log = out if args.format == "table" else console(stderr=True)
    if cache_summary():
        log.print(cache_summary(), markup=False)
    if report.skipped:
        log.print(f"resumed: kept {len(report.skipped)} finished sequence(s): "
                  f"{', '.join(report.skipped)}", markup=False)
    for name, why in report.replayed.items():
        log.print(f"replayed {name}: {why}", markup=False, soft_wrap=True)
    for name, files in report.restamped.items():
        log.print(f"re-stamped {name}: kept across your edit of {', '.join(files)}",
                  markup=False, soft_wrap=True)
    if report.scores is None:
        log.print(f"{len(report.records)} sequence(s) written to {report.out / 'data'} "
                  "(no ground truth in this split, nothing to score)", markup=False)
    else:
        fps = {name: record.fps for name, record in report.records.items()}
        print_metrics(out, report.scores.per_sequence, report.scores.combined,
                       f"{args.agent} on {args.env}", _columns(args.env, env_given),
                       args.format, fps, coverage=report.scores.coverage)
        if report.repetitions is not None and args.format == "table":
            out.print(spread_table(report.repetitions, _columns(args.env, env_given),
                                   out.width))
        undefined = sorted(name for name, values in report.scores.per_sequence.items()
                           if any(not _defined(v) for v in values.values()))
        if undefined:
            log.print(f"(undefined metrics, shown as - or nan, in {', '.join(undefined)}: "
                      "nothing there to score under the benchmark's rules; the environment's "
                      "page in docs/envs/ says when)", markup=False)
    log.print(f"metrics: {report.out / 'metrics.json'}", markup=False)
    others = sorted({p.stem for p in (report.out / "sequences").glob("*.json")}
                    - set(args.sequences or ()))
    if args.sequences and others:
        log.print(f"(metrics.json covers the {len(args.sequences)} sequence(s) asked for; "
                  f"{len(others)} other finished sequence(s) in {report.out} are kept but not "
                  "in it: run without --sequences to score them all)", markup=False)
    return 0


def _columns(env_id: str, env_given: dict[str, Any]) -> tuple[str, ...]:
    """The table columns of the run's benchmark instance (a MOT class map adds its classes)."""
    return benchmark_for(env_id, **env_given).columns


def spread_table(repeated: dict[str, Any], columns: tuple[str, ...], width: int) -> Any:
    """A table of each metric's mean [min, max] over the repetitions, per sequence.

    The leading columns that fit in ``width``; the title counts those left to metrics.json.
    """
    spread = repeated["spread"]
    rows = {**spread["per_sequence"], "COMBINED": spread["combined"]}
    cells = {label: {m: f"{format_cell(m, v['mean'])} [{format_cell(m, v['min'])}, "
                        f"{format_cell(m, v['max'])}]" for m, v in stats.items()}
             for label, stats in rows.items()}
    shown, used = [], max(len(label) for label in rows) + 4
    for name in table_columns(columns, list(rows.values())):
        used += max(len(name), *(len(c.get(name, "-")) for c in cells.values())) + 3
        if used > width and shown:
            break
        shown.append(name)
    left = len(table_columns(columns, list(rows.values()))) - len(shown)
    title = f"spread over {repeated['repeats']} repetitions: mean [min, max]" + (
        f" ({left} more column(s) in metrics.json)" if left else "")
    table = Table(title=escape(title), title_justify="left")
    table.add_column("sequence", no_wrap=True)
    for name in shown:
        table.add_column(name, justify="right", no_wrap=True)
    for label, row in cells.items():
        table.add_row(label, *(escape(row.get(m, "-")) for m in shown),
                      style="bold" if label == "COMBINED" else None)
    return table
