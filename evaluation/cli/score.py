"""``unitrack score``: score a folder of result files in the official format."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rich.console import Console

from unitrack_env.benchmarks import benchmark_for
from unitrack_env.io import atomic_write_text

from ..analysis.tables import json_safe
from .common import check_env_id, console, env_kwargs, format_option, names, print_metrics

EXAMPLES = """examples:
  unitrack score --env UniTrack/MOT17-v0 --root data/MOT17 --results runs/mot17/data
  unitrack score --benchmark MOT17 --gt data/MOT17/train --results runs/mot17/data --format csv
"""


def add_arguments(sc: argparse.ArgumentParser) -> None:
    """The options of ``unitrack score``."""
    sc.add_argument("--env", help="environment id whose data and metrics to use")
    sc.add_argument("--root", help="benchmark folder (with --env; default: synthetic data)")
    sc.add_argument("--split", help="split folder (with --env)")
    sc.add_argument("--env-arg", action="append", metavar="KEY=VALUE",
                    help="another environment argument (with --env, repeatable)")
    sc.add_argument("--benchmark", help="MOTChallenge shortcut: MOT15, MOT16, MOT17 or MOT20")
    sc.add_argument("--gt", help="MOTChallenge shortcut: folder of sequences with gt/gt.txt")
    sc.add_argument("--results", required=True,
                    help="results folder (as written by `unitrack evaluate` under <out>/data)")
    sc.add_argument("--sequences", type=names,
                    help="comma-separated sequence names (default: all files)")
    sc.add_argument("--allow-missing", action="store_true",
                    help="score the sequences that have a result file even when others of the "
                    "split have none (refused by default: the combined row would not be the "
                    "benchmark's)")
    sc.add_argument("--out", help="also write the metrics as JSON to this file")
    format_option(sc)


def run(args: argparse.Namespace, out: Console) -> int:
    """Run ``unitrack score``."""
    if args.env:
        given = env_kwargs(args)
        bench = benchmark_for(check_env_id(args.env), **given)
        chosen = given.get("sequences")  # --env-arg sequences=...: those with gt
        report = bench.score_folder(Path(args.results), args.sequences or (
            bench.scorable(chosen) if chosen else None), allow_missing=args.allow_missing)
        columns = bench.columns
    elif args.benchmark and args.gt:
        # lazy: start-up cost (TrackEval: `unitrack score --help` 0.22 s, else 0.83 s)
        from unitrack_env.benchmarks.motchallenge import MOTChallengeBenchmark, score_split_folder

        report = score_split_folder(args.gt, args.results, args.benchmark, args.sequences,
                                    allow_missing=args.allow_missing)
        columns = MOTChallengeBenchmark.columns
    else:
        raise ValueError("score needs --env ID [--root DIR] [--split S], or (MOTChallenge) "
                         "--benchmark MOT17 --gt DIR")
    print_metrics(out, report.per_sequence, report.combined, str(args.results), columns,
                   args.format, coverage=report.coverage)
    if report.missing:
        console(stderr=True).print(f"(--allow-missing: COMBINED covers {report.coverage}; "
                                    f"no result file for {', '.join(report.missing)})",
                                    markup=False)
    if args.out:
        atomic_write_text(args.out, json.dumps(json_safe(json.loads(report.to_json())),
                                               indent=2))
        console(stderr=True).print(f"metrics: {args.out}", markup=False)
    return 0
