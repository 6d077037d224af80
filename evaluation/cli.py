"""The unitrack command line: evaluate trackers on tracking benchmarks, score, render, check.

Every user error (an unknown id or option, bad data, a full disk, an agent that raises) is
reported as one line starting with "error:", printed literally; ``--debug`` adds the
traceback. Finished sequences are always kept: run the same command again to resume.
"""

from __future__ import annotations

import argparse
import difflib
import os
import sys
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rich.console import Console

from .cli_types import names, non_negative_float, positive_float, positive_int
from .progress import one_line_warnings
from .watchdog import DEFAULT_STEP_TIMEOUT, Terminated, sigterm_stops

#: gym.make's own keyword arguments, accepted by every environment.
GYM_MAKE_OPTIONS: dict[str, Any] = {
    "max_episode_steps": int | None, "autoreset": bool, "disable_env_checker": bool | None,
}

EXAMPLES = {
    "evaluate": """examples:
  unitrack evaluate --env UniTrack/MOT16-v0 --agent iou --out runs/quickstart
  unitrack evaluate --env UniTrack/MOT17-v0 --root data/MOT17 --agent unitrack \\
      --agent-arg weights=moco_v2.pth --workers 2 --out runs/mot17
  unitrack evaluate --env UniTrack/MOT16-v0 --agent my_trackers:Nearest --out runs/mine
  unitrack evaluate --env UniTrack/OTB-v0 --agent trackers/sot.py:MySOT --out runs/sot
""",
    "score": """examples:
  unitrack score --env UniTrack/MOT17-v0 --root data/MOT17 --results runs/mot17/data
  unitrack score --benchmark MOT17 --gt data/MOT17/train --results runs/mot17/data --format csv
""",
    "scorecard": """examples:
  unitrack scorecard --model imagenet-lite0 --model random --data data --out runs/sc
  unitrack scorecard --model moco_v2.pth,arch=resnet50,layer=layer3,label=MoCo-v2 \\
      --model imagenet-lite0 --tasks sot,vos,mot --workers 2 --out runs/sc
  unitrack scorecard --backend ray --address auto --model imagenet-lite0 --out runs/sc
  unitrack scorecard --compare runs/a/scorecard.json runs/b/scorecard.json --out runs/both
""",
    "render": """examples:
  unitrack render --env UniTrack/MOT16-v0 --agent iou --sequence SYN-01 --out syn01.mp4
""",
}


def _console(stderr: bool = False) -> Console:
    console = Console(stderr=stderr, highlight=False, soft_wrap=stderr)
    if not console.is_terminal and "COLUMNS" not in os.environ:
        console.width = 100_000  # a file or a pipe gets every column and unbroken lines
    return console


def _check_env_id(env_id: str) -> str:
    """The env id, or a ValueError with the closest registered ids."""
    import unitrack_env

    ids = unitrack_env.env_ids()
    if env_id in ids:
        return env_id
    close = difflib.get_close_matches(env_id, ids, n=3, cutoff=0.5)
    hint = f"did you mean {' or '.join(close)}? " if close else ""
    raise ValueError(f"unknown environment '{env_id}'; {hint}`unitrack list` shows all ids")


def _env_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """The environment arguments from the command line, checked against the env's options."""
    import gymnasium as gym

    from unitrack_env.agents.options import parse_options

    env_id = _check_env_id(args.env)
    import unitrack_env

    unitrack_env.register_all()
    cls = gym.envs.registration.load_env_creator(gym.spec(env_id).entry_point)
    given = list(args.env_arg or [])
    for name in ("split", "detections"):  # checked like --env-arg: OTB has neither
        if getattr(args, name, None):
            given.append(f"{name}={getattr(args, name)}")
    kwargs = parse_options(cls, given, agent=env_id, kind="environment",
                           extra=GYM_MAKE_OPTIONS)
    if args.root is not None:
        kwargs["root"] = str(Path(args.root).expanduser().resolve())
    return kwargs


def _agent_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    from unitrack_env.agents.base import agent_class
    from unitrack_env.agents.options import parse_options

    return parse_options(agent_class(args.agent), args.agent_arg or [], agent=args.agent)


def _print_metrics(console: Console, per_sequence: dict, combined: dict | None, title: str,
                   columns: tuple, fmt: str, fps: dict | None = None, coverage: str = "") -> None:
    from .tables import metrics_csv, metrics_json, metrics_table

    if fmt == "json":
        console.print(metrics_json(per_sequence, combined), markup=False, soft_wrap=True)
    elif fmt == "csv":
        console.print(metrics_csv(per_sequence, combined, columns), markup=False, end="",
                      soft_wrap=True)
    else:
        table, dropped = metrics_table(per_sequence, combined, title, fps, columns,
                                       width=console.width, coverage=coverage)
        console.print(table)
        if dropped:
            console.print(f"({len(dropped)} more column(s) do not fit: {', '.join(dropped)}; "
                          "--format csv shows every metric)", markup=False)


def _defined(value: Any) -> bool:
    return value is not None and not (isinstance(value, float) and value != value)


def _cmd_evaluate(args: argparse.Namespace, console: Console) -> int:
    from unitrack_env.benchmarks import benchmark_class

    from .runner import run

    env_kwargs = _env_kwargs(args)
    agent_kwargs = _agent_kwargs(args)
    from .cache_cli import feature_cache_report

    with feature_cache_report(args.agent, agent_kwargs) as cache_summary:
        report = run(args.env, args.agent, out=args.out, env_kwargs=env_kwargs,
                     agent_kwargs=agent_kwargs,
                     sequences=args.sequences,
                     workers=args.workers, overwrite=args.overwrite, isolate=not args.in_process,
                     progress=not args.quiet and args.format == "table",
                     step_timeout=args.step_timeout, restamp=args.restamp,
                     backend=args.backend, address=args.address)
    log = console if args.format == "table" else _console(stderr=True)
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
        _print_metrics(console, report.scores.per_sequence, report.scores.combined,
                       f"{args.agent} on {args.env}", benchmark_class(args.env).columns,
                       args.format, fps, coverage=report.scores.coverage)
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


def _cmd_score(args: argparse.Namespace, console: Console) -> int:
    import json

    if args.env:
        from unitrack_env.benchmarks import benchmark_for

        env_kwargs = _env_kwargs(args)
        bench = benchmark_for(_check_env_id(args.env), **env_kwargs)
        chosen = env_kwargs.get("sequences")  # --env-arg sequences=...: those with gt
        report = bench.score_folder(Path(args.results), args.sequences or (
            bench.scorable(chosen) if chosen else None), allow_missing=args.allow_missing)
        columns = bench.columns
    elif args.benchmark and args.gt:
        from unitrack_env.benchmarks.motchallenge import MOTChallengeBenchmark, score_split_folder

        report = score_split_folder(args.gt, args.results, args.benchmark, args.sequences,
                                    allow_missing=args.allow_missing)
        columns = MOTChallengeBenchmark.columns
    else:
        raise ValueError("score needs --env ID [--root DIR] [--split S], or (MOTChallenge) "
                         "--benchmark MOT17 --gt DIR")
    _print_metrics(console, report.per_sequence, report.combined, str(args.results), columns,
                   args.format, coverage=report.coverage)
    if report.missing:
        _console(stderr=True).print(f"(--allow-missing: COMBINED covers {report.coverage}; "
                                    f"no result file for {', '.join(report.missing)})",
                                    markup=False)
    if args.out:
        from unitrack_env.io import atomic_write_text

        from .runner import json_safe

        atomic_write_text(args.out, json.dumps(json_safe(json.loads(report.to_json())),
                                               indent=2))
        _console(stderr=True).print(f"metrics: {args.out}", markup=False)
    return 0


def _cmd_render(args: argparse.Namespace, console: Console) -> int:
    from .video import check_video_path, render_episode

    check_video_path(args.out)
    frames = render_episode(args.env, args.agent, args.sequence, args.out,
                            env_kwargs=_env_kwargs(args), agent_kwargs=_agent_kwargs(args),
                            fps=args.fps)
    console.print(f"wrote {frames} frames to {args.out}", markup=False)
    return 0


def _cmd_list(args: argparse.Namespace, console: Console) -> int:
    from rich.table import Table

    from unitrack_env.agents.base import agent_class, available_agents
    from unitrack_env.agents.loading import entry_point_agents
    from unitrack_env.registration import variants

    envs = Table(title="environments", title_justify="left")
    envs.add_column("id", no_wrap=True)
    envs.add_column("task")
    for variant in variants():
        envs.add_row(variant.env_id, variant.task)
    console.print(envs)
    plugins = entry_point_agents()
    agents = Table(title="agents (--agent NAME, or module:Class, or file.py:Class)",
                   title_justify="left")
    for column in ("name", "tasks", "from"):
        agents.add_column(column, no_wrap=column == "name")
    for name in available_agents():
        try:
            tasks = ", ".join(getattr(agent_class(name), "tasks", ()))
        except Exception as exc:  # a broken plug-in must not hide the others
            tasks = f"(cannot load: {type(exc).__name__})"
        source = f"plug-in {plugins[name].value}" if name in plugins else "unitrack-env"
        agents.add_row(name, tasks, source)
    console.print(agents)
    return 0


def _cmd_doctor(args: argparse.Namespace, console: Console) -> int:
    from .doctor import diagnose

    findings = diagnose()
    marks = {"ok": "ok     ", "warn": "note   ", "problem": "PROBLEM"}
    for finding in findings:
        console.print(f"{marks[finding.status]} {finding.check}: {finding.detail}", markup=False,
                      soft_wrap=True)
        if finding.fix and finding.status != "ok":
            console.print(f"        fix: {finding.fix}", markup=False, soft_wrap=True)
    problems = sum(f.status == "problem" for f in findings)
    console.print(f"{problems} problem(s)" if problems else "no problems found", markup=False)
    return 1 if problems else 0


def _env_options(p: argparse.ArgumentParser, *, agent: bool = True) -> None:
    p.add_argument("--env", required=True, help="environment id, e.g. UniTrack/MOT17-v0 "
                   "(`unitrack list` shows all)")
    p.add_argument("--root", help="benchmark folder as the benchmark ships it (default: "
                   "$UNITRACK_DATA/<benchmark>, else the embedded synthetic data)")
    p.add_argument("--split", help="split folder, e.g. train, val or test")
    p.add_argument("--detections", help="association tasks: 'public' (the benchmark's "
                   "detections) or a folder of <sequence>.txt files in the same format")
    p.add_argument("--env-arg", action="append", metavar="KEY=VALUE",
                   help="another environment argument, checked against the environment's "
                   "options (repeatable), e.g. --env-arg min_score=0.3")
    if agent:
        p.add_argument("--agent", required=True, help="agent: a name from `unitrack list`, "
                       "package.module:ClassName, or path/to/file.py:ClassName")
        p.add_argument("--agent-arg", action="append", metavar="KEY=VALUE",
                       help="agent option, checked against the agent's options by name and "
                       "type (repeatable), e.g. --agent-arg weights=moco.pth")


def _format_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--format", choices=("table", "json", "csv"), default="table",
                   help="how to print the metrics (default: a table fitted to the terminal)")


def _add_evaluate(ev: argparse.ArgumentParser) -> None:
    _env_options(ev)
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
    ev.add_argument("--quiet", action="store_true", help="no progress bar")
    _format_option(ev)
    ev.set_defaults(func=_cmd_evaluate)


def _add_score(sc: argparse.ArgumentParser) -> None:
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
    _format_option(sc)
    sc.set_defaults(func=_cmd_score)


def _add_render(rd: argparse.ArgumentParser) -> None:
    _env_options(rd)
    rd.add_argument("--sequence", required=True,
                    help="the sequence to play (its name in the data set, e.g. MOT17-04-FRCNN)")
    rd.add_argument("--out", required=True,
                    help="video file: .mp4 (H.264, needs the video extra) or .avi (MJPEG)")
    rd.add_argument("--fps", type=positive_float, default=None,
                    help="video frame rate (default: the sequence's)")
    rd.set_defaults(func=_cmd_render)


def _add_commands(sub: Any) -> None:
    from .cli_scorecard import add_options as add_scorecard_options

    def command(name: str, help_text: str) -> argparse.ArgumentParser:
        return sub.add_parser(name, help=help_text, description=help_text,
                              epilog=EXAMPLES.get(name),
                              formatter_class=argparse.RawDescriptionHelpFormatter)

    _add_evaluate(command("evaluate", "run an agent on every sequence of an environment and "
                          "score it"))
    _add_score(command("score", "score a folder of result files in the official format"))
    _add_render(command("render", "write a video of an agent's tracks on one sequence"))
    add_scorecard_options(command("scorecard", "play every task's UniTrack head with each "
                                  "appearance model and draw the paper's table and radar chart"))
    command("list", "list environments and agents").set_defaults(func=_cmd_list)
    command("doctor", "check that this environment can run and score every task (exit "
            "status 1 on a problem, with the fix)").set_defaults(func=_cmd_doctor)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``unitrack``."""
    import unitrack_env

    parser = argparse.ArgumentParser(
        prog="unitrack", description=__doc__.split("\n")[0],
        epilog="`unitrack COMMAND --help` shows each command's options and examples.",
    )
    parser.add_argument("--version", action="version",
                        version=f"unitrack-env {unitrack_env.__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback of an error")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_commands(sub)
    from .cache_cli import add_parser as add_cache_parser

    add_cache_parser(sub)  # unitrack cache info|prune|clear
    from .cli_report import add_parsers as add_report_parsers

    add_report_parsers(sub)  # unitrack events|compare|report
    from .cli_tune import add_parser as add_tune_parser

    add_tune_parser(sub)  # unitrack tune
    from .cli_plot import add_parser as add_plot_parser

    add_plot_parser(sub)  # unitrack plot
    return parser


def _error_text(exc: BaseException) -> str:
    if isinstance(exc, KeyError) and exc.args and type(exc) is KeyError:
        return str(exc.args[0])
    text = str(exc) or type(exc).__name__
    known = (ValueError, KeyError, OSError, ImportError, RuntimeError)
    return text if isinstance(exc, known) else f"{type(exc).__name__}: {text}"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``unitrack`` command; returns the exit status."""
    args = build_parser().parse_args(argv)
    console = _console()
    try:
        with one_line_warnings(), sigterm_stops():
            return args.func(args, console)
    except KeyboardInterrupt as stop:  # Ctrl-C, or SIGTERM (Terminated): exit 130 or 143
        what = "terminated (SIGTERM)" if isinstance(stop, Terminated) else "interrupted"
        _console(stderr=True).print(f"{what}: finished sequences are kept; run the same "
                                    "command again to resume", markup=False)
        return 143 if isinstance(stop, Terminated) else 130
    except Exception as exc:
        errors = _console(stderr=True)
        if args.debug:
            errors.print("".join(traceback.format_exception(exc)), markup=False)
        from .runner import RunFailed

        errors.print(f"error: {_error_text(exc)}", markup=False)
        if not args.debug:
            errors.print("(--debug shows the traceback)", markup=False, style="dim")
        return 1 if isinstance(exc, RunFailed) else 2


if __name__ == "__main__":
    sys.exit(main())
