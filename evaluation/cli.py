"""The ``unitrack`` command line.

Commands:
    unitrack evaluate --env ID [--root DIR] --agent NAME --out DIR
    unitrack score --env ID [--root DIR] --results DIR [--out metrics.json]
    unitrack score --benchmark MOT17 --gt DIR --results DIR        (MOTChallenge shortcut)
    unitrack render --env ID [--root DIR] --agent NAME --sequence NAME --out video.mp4
    unitrack list
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

#: Columns of the results table per task (the metrics' official names), in this order.
TASK_COLUMNS: dict[str, tuple[str, ...]] = {
    "mot": ("HOTA", "DetA", "AssA", "MOTA", "MOTP", "IDF1", "IDSW", "CLR_FP", "CLR_FN",
            "MT", "ML"),
    "mots": ("HOTA", "DetA", "AssA", "sMOTSA", "MOTSA", "MOTSP", "IDF1", "IDSW", "CLR_FP",
             "CLR_FN"),
    "vis": ("AP", "AP50", "AP75", "AR"),
    "posetrack": ("MOTA", "IDF1", "IDSW", "MOTP", "Precision", "Recall"),
    "sot": ("AUC", "Precision@20px", "AverageOverlap"),
    "vos": ("J&F-Mean", "J-Mean", "J-Recall", "J-Decay", "F-Mean", "F-Recall", "F-Decay"),
    "pose-prop": ("PCK@0.1", "PCK@0.2"),
}
#: Metrics that are counts (printed as integers, not percentages).
COUNT_METRICS = frozenset({"IDSW", "CLR_FP", "CLR_FN", "CLR_TP", "MT", "ML", "PT", "Frag"})
#: Columns shown for a task the table does not know: the first metrics found.
FALLBACK_COLUMNS = 8


def _parse_value(text: str) -> Any:
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def parse_key_values(items: Sequence[str] | None, what: str) -> dict[str, Any]:
    """Parse ``key=value`` strings; values are Python literals when they parse as such."""
    out: dict[str, Any] = {}
    for item in items or ():
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise SystemExit(f"error: {what} '{item}' must look like key=value")
        out[key.replace("-", "_")] = _parse_value(value)
    return out


def table_columns(task: str, rows: list[dict[str, float]]) -> list[str]:
    """The task's columns that occur in ``rows`` (or the first metrics, for unknown tasks)."""
    present = {key for row in rows for key in row}
    if task in TASK_COLUMNS:
        return [name for name in TASK_COLUMNS[task] if name in present]
    seen: list[str] = []
    for row in rows:
        seen += [key for key in row if key not in seen]
    return seen[:FALLBACK_COLUMNS]


def metrics_table(
    per_sequence: dict[str, dict[str, float]],
    combined: dict[str, float] | None,
    title: str,
    fps: dict[str, float] | None = None,
    task: str = "mot",
) -> Table:
    """Build a rich table: one row per sequence plus the combined row (percent, counts)."""
    rows = list(per_sequence.values()) + ([combined] if combined else [])
    columns = table_columns(task, rows)
    table = Table(title=title)
    table.add_column("sequence")
    for name in columns:
        table.add_column(name, justify="right")
    if fps is not None:
        table.add_column("FPS", justify="right")

    def cells(metrics: dict[str, float]) -> list[str]:
        out = []
        for name in columns:
            value = metrics.get(name)
            if value is None or value != value:  # missing or NaN (nothing to score)
                out.append("-")
            elif name in COUNT_METRICS:
                out.append(f"{value:.0f}")
            else:
                out.append(f"{100 * value:.1f}")
        return out

    for name, metrics in per_sequence.items():
        extra = [f"{fps[name]:.1f}" if name in fps else "-"] if fps is not None else []
        table.add_row(name, *cells(metrics), *extra)
    if combined is not None:
        extra = [""] if fps is not None else []
        table.add_row("COMBINED", *cells(combined), *extra, style="bold")
    return table


def _env_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    kwargs = parse_key_values(args.env_arg, "--env-arg")
    if args.root is not None:
        kwargs["root"] = str(Path(args.root).resolve())
    if getattr(args, "split", None):
        kwargs["split"] = args.split
    if getattr(args, "detections", None):
        kwargs["detections"] = args.detections
    return kwargs


def _cmd_evaluate(args: argparse.Namespace, console: Console) -> int:
    from unitrack_env.evaluation.runner import run

    sequences = args.sequences.split(",") if args.sequences else None
    report = run(
        args.env,
        args.agent,
        out=args.out,
        env_kwargs=_env_kwargs(args),
        agent_kwargs=parse_key_values(args.agent_arg, "--agent-arg"),
        sequences=sequences,
        workers=args.workers,
        overwrite=args.overwrite,
        progress=not args.quiet,
    )
    if report.skipped:
        console.print(f"resumed: {len(report.skipped)} finished sequence(s) were kept: "
                      f"{', '.join(report.skipped)}")
    fps = {name: record.fps for name, record in report.records.items()}
    if report.scores is None:
        console.print(f"{len(report.records)} sequence(s) written to {report.out / 'data'} "
                      "(no ground truth in this split, nothing to score)")
    else:
        import unitrack_env

        console.print(metrics_table(report.scores.per_sequence, report.scores.combined,
                                    f"{args.agent} on {args.env}", fps,
                                    task=unitrack_env.task_of(args.env)))
    console.print(f"metrics: {report.out / 'metrics.json'}")
    return 0


def _cmd_score(args: argparse.Namespace, console: Console) -> int:
    sequences = args.sequences.split(",") if args.sequences else None
    if args.env:
        import gymnasium as gym

        import unitrack_env

        env = gym.make(args.env, **_env_kwargs(args))
        base = env.unwrapped
        names = sequences or [n for n in base.sequence_names if base.has_ground_truth(n)]
        report = base.score_folder(Path(args.results), names)
        task = unitrack_env.task_of(args.env)
        env.close()
    elif args.benchmark and args.gt:
        from unitrack_env.metrics.motchallenge import score_folder

        report = score_folder(args.gt, args.results, benchmark=args.benchmark,
                              sequences=sequences)
        task = "mot"
    else:
        raise ValueError("score needs --env ID [--root DIR] [--split S], or (MOTChallenge) "
                         "--benchmark MOT17 --gt DIR")
    console.print(metrics_table(report.per_sequence, report.combined, f"{args.results}",
                                task=task))
    if args.out:
        from unitrack_env.evaluation.runner import json_safe

        Path(args.out).write_text(json.dumps(json_safe(json.loads(report.to_json())), indent=2))
        console.print(f"metrics: {args.out}")
    return 0


def _cmd_render(args: argparse.Namespace, console: Console) -> int:
    from unitrack_env.evaluation.video import render_episode

    frames = render_episode(
        args.env, args.agent, args.sequence, args.out,
        env_kwargs=_env_kwargs(args),
        agent_kwargs=parse_key_values(args.agent_arg, "--agent-arg"),
        fps=args.fps,
    )
    console.print(f"wrote {frames} frames to {args.out}")
    return 0


def _cmd_list(args: argparse.Namespace, console: Console) -> int:
    import unitrack_env
    from unitrack_env.agents import available_agents

    table = Table(title="environments")
    table.add_column("id")
    table.add_column("task")
    for variant in unitrack_env.VARIANTS:
        table.add_row(variant.env_id, variant.task)
    console.print(table)
    console.print("agents: " + ", ".join(available_agents()))
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``unitrack``."""
    parser = argparse.ArgumentParser(prog="unitrack", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)

    def env_options(p: argparse.ArgumentParser) -> None:
        p.add_argument("--env", required=True, help="environment id, e.g. UniTrack/MOT17-v0")
        p.add_argument("--root", help="benchmark folder (default: embedded synthetic data)")
        p.add_argument("--split", help="split folder, e.g. train or test")
        p.add_argument("--detections", help="'public' or a folder of <sequence>.txt files")
        p.add_argument("--env-arg", action="append", metavar="KEY=VALUE",
                       help="extra environment argument (repeatable)")
        p.add_argument("--agent", required=True, help="agent name (see `unitrack list`)")
        p.add_argument("--agent-arg", action="append", metavar="KEY=VALUE",
                       help="agent argument, e.g. --agent-arg min_score=0.5 (repeatable)")

    ev = sub.add_parser("evaluate", help="run an agent on every sequence and score it")
    env_options(ev)
    ev.add_argument("--out", required=True, help="output folder (resumed if it exists)")
    ev.add_argument("--sequences", help="comma-separated sequence names (default: all)")
    ev.add_argument("--workers", type=int, default=1, help="parallel worker processes")
    ev.add_argument("--overwrite", action="store_true", help="discard a previous run in --out")
    ev.add_argument("--quiet", action="store_true", help="no progress bar")
    ev.set_defaults(func=_cmd_evaluate)

    sc = sub.add_parser("score", help="score a folder of result files in the official format")
    sc.add_argument("--env", help="environment id whose data and metrics to use")
    sc.add_argument("--root", help="benchmark folder (with --env; default: synthetic data)")
    sc.add_argument("--split", help="split folder (with --env)")
    sc.add_argument("--env-arg", action="append", metavar="KEY=VALUE",
                    help="extra environment argument (with --env, repeatable)")
    sc.add_argument("--benchmark", help="MOTChallenge shortcut: MOT15, MOT16, MOT17 or MOT20")
    sc.add_argument("--gt", help="MOTChallenge shortcut: folder of sequences with gt/gt.txt")
    sc.add_argument("--results", required=True,
                    help="results folder (as written by `unitrack evaluate` under <out>/data)")
    sc.add_argument("--sequences", help="comma-separated sequence names (default: all files)")
    sc.add_argument("--out", help="write the metrics as JSON here")
    sc.set_defaults(func=_cmd_score)

    rd = sub.add_parser("render", help="write a video of an agent's tracks on one sequence")
    env_options(rd)
    rd.add_argument("--sequence", required=True)
    rd.add_argument("--out", required=True, help="video file (.mp4 or .avi)")
    rd.add_argument("--fps", type=float, default=None,
                    help="video frame rate (default: the sequence's)")
    rd.set_defaults(func=_cmd_render)

    ls = sub.add_parser("list", help="list environments and agents")
    ls.set_defaults(func=_cmd_list)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``unitrack`` command."""
    args = build_parser().parse_args(argv)
    # Tables are wide; rich assumes 80 columns when output is not a terminal.
    console = Console(width=None if sys.stdout.isatty() else 160)
    try:
        return args.func(args, console)
    except KeyboardInterrupt:
        console.print("[yellow]interrupted[/]: finished sequences are kept; run the same "
                      "command again to resume")
        return 130
    except (ValueError, KeyError, FileNotFoundError, ImportError) as exc:
        message = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        console.print(f"[red]error:[/] {message}", highlight=False)
        return 2


if __name__ == "__main__":
    sys.exit(main())

