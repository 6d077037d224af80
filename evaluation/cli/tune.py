"""The ``unitrack tune`` command: its options, the search's progress, and what it found."""

from __future__ import annotations

import argparse
from dataclasses import asdict
from typing import Any

from rich.console import Console
from rich.table import Table

from .common import agent_kwargs, env_kwargs, env_options, names, positive_int

EXAMPLES = """examples:
  unitrack tune --env UniTrack/MOT16-v0 --agent unitrack --tune-sequences SYN-01 \\
      --validation-sequences SYN-02 --metric IDF1 --trials 8 --out runs/tune \\
      --space new_track_score=0.3..0.9 --space appearance_threshold=0.5..0.9 \\
      --space use_motion=True|False
"""


def add_arguments(tp: argparse.ArgumentParser) -> None:
    """The options of ``unitrack tune``."""
    env_options(tp)
    tp.add_argument("--space", action="append", required=True,
                    metavar="NAME=LOW..HIGH[:log] | NAME=A|B",
                    help="an option to search (repeatable): a range (float when a bound has "
                    "a decimal point, else int) or choices, e.g. iou_threshold=0.3..0.7")
    tp.add_argument("--tune-sequences", type=names, required=True,
                    help="comma-separated sequences the search scores settings on")
    tp.add_argument("--validation-sequences", type=names, required=True,
                    help="comma-separated unseen sequences: best setting vs defaults")
    tp.add_argument("--metric", required=True, help="the combined metric to optimise, e.g. "
                    "IDF1 or HOTA (the benchmark's column name)")
    tp.add_argument("--minimize", action="store_true",
                    help="minimise the metric (default: maximise)")
    tp.add_argument("--trials", type=positive_int, default=20,
                    help="complete trials in all, counting those of an earlier, interrupted "
                    "run in --out (default: 20)")
    tp.add_argument("--backend", choices=("optuna", "ray"), default="optuna",
                    help="optuna: trials one after another, study in --out/optuna.db; ray: "
                    "trials as Ray Tune trials (OptunaSearch), experiment in --out/ray "
                    "(default: optuna)")
    tp.add_argument("--address", help="with --backend ray: the cluster to join, auto or "
                    "ray://host:port (default: a local Ray); --out must be on a file system "
                    "every node sees")
    tp.add_argument("--seed", type=int, default=0, help="sampler seed (default: 0)")
    tp.add_argument("--out", required=True, help="the search's folder: optuna.db, one run "
                    "folder per trial, validation runs, tune.json (an existing search resumes)")


def _spec(args: argparse.Namespace) -> Any:
    # lazy: start-up cost (scipy, TrackEval: `unitrack tune --help` 0.25 s, else 1.50 s)
    from ..tune.search import TuneSpec, parse_dimension

    space = [asdict(parse_dimension(text)) for text in args.space]
    for d in space:
        d["choices"] = list(d["choices"])
    return TuneSpec(args.env, args.agent, space, args.metric,
                    "minimize" if args.minimize else "maximize", list(args.tune_sequences),
                    list(args.validation_sequences), env_kwargs(args), agent_kwargs(args))


def _setting(params: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v!r}"
                     for k, v in params.items())


def run(args: argparse.Namespace, console: Console) -> int:
    """Run ``unitrack tune``."""
    # lazy: start-up cost (scipy, TrackEval: `unitrack tune --help` 0.25 s, else 1.50 s)
    from ..tune.ray_trials import check_ray_tune, ray_search
    from ..tune.search import tune

    if args.address is not None and args.backend != "ray":
        raise ValueError("--address goes with --backend ray")
    spec = _spec(args)
    log = Console(stderr=True, highlight=False, soft_wrap=True)

    def on_trial(row: dict[str, Any]) -> None:
        log.print(f"trial {row['number']}: {spec.metric} {100 * row['value']:.1f} in "
                  f"{row['seconds']:.1f} s, {row['cpu_seconds']:.1f} s CPU "
                  f"({_setting(row['params'])})", markup=False)
        if row["feature_cache"]:
            log.print(f"  {row['feature_cache']}", markup=False)

    if args.backend == "ray":
        search = {"search": ray_search(args.address), "backend": "ray",
                  "check": check_ray_tune}
    else:
        search = {}
    result = tune(spec, out=args.out, trials=args.trials, seed=args.seed, on_trial=on_trial,
                  **search)
    _print_result(console, spec, result)
    console.print(f"wrote {args.out}/tune.json", markup=False)
    return 0


def _print_result(console: Console, spec: Any, result: dict[str, Any]) -> None:
    table = Table(title=f"search history ({spec.metric} on {', '.join(spec.tune_sequences)})",
                  title_justify="left")
    for column in ("trial", "state", spec.metric, "seconds", "setting"):
        table.add_column(column, justify="right" if column != "setting" else "left")
    for row in result["history"]:
        value = "-" if row["value"] is None else f"{100 * row['value']:.1f}"
        seconds = "-" if row["seconds"] is None else f"{row['seconds']:.1f}"
        table.add_row(str(row["number"]), row["state"].lower(), value, seconds,
                      _setting(row["params"]))
    console.print(table)
    best = result["best"]
    console.print(f"best: trial {best['number']}, {spec.metric} {100 * best['value']:.1f} "
                  f"({_setting(best['params'])})", markup=False, soft_wrap=True)
    cost = result["cost"]
    if cost:
        console.print(f"cost: first trial {cost['first_seconds']:.1f} s, later trials "
                      f"{cost['later_median_seconds']:.1f} s (median), ratio "
                      f"{cost['ratio']:.2f}; CPU {cost['first_cpu_seconds']:.1f} s vs "
                      f"{cost['later_median_cpu_seconds']:.1f} s, ratio {cost['cpu_ratio']:.2f}"
                      " (later trials read the backbone's features from the cache)",
                      markup=False, soft_wrap=True)
    elif len(result["history"]) > 1:
        console.print("cost: not measured (the first trial, the one that ran the backbone, "
                      "was interrupted and resumed)", markup=False, soft_wrap=True)
    v = result["validation"]
    line = (f"validation ({', '.join(v['sequences'])}): {spec.metric} best "
            f"{_percent(v['best'])} vs defaults {_percent(v['defaults'])}")
    if "diff" in v:
        line += (f", difference {100 * v['diff']:+.1f} [95% interval {100 * v['low']:+.1f}, "
                 f"{100 * v['high']:+.1f}]" + ("" if v["significant"] else
                                                " (not significant)"))
    console.print(line, markup=False, soft_wrap=True)
    for note in [v.get("note"), *v.get("notes", [])]:
        if note:
            console.print(f"  note: {note}", markup=False, soft_wrap=True)


def _percent(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.1f}"

