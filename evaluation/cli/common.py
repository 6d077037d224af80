"""What the ``unitrack`` commands share: the console, error text, option types and options.

An argument type refuses a value in one line (argparse prints it); :func:`error_text` is the one
line ``unitrack`` prints for any other error.
"""

from __future__ import annotations

import argparse
import difflib
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
from rich.console import Console

import unitrack_env
from unitrack_env.agents.base import agent_class
from unitrack_env.agents.options import parse_options

from ..analysis.tables import metrics_csv, metrics_json, metrics_table

#: gym.make's own keyword arguments, accepted by every environment.
GYM_MAKE_OPTIONS: dict[str, Any] = {
    "max_episode_steps": int | None, "autoreset": bool, "disable_env_checker": bool | None,
}


def console(stderr: bool = False) -> Console:
    """A console for the command's output (``stderr``: for notes and errors)."""
    out = Console(stderr=stderr, highlight=False, soft_wrap=stderr)
    if not out.is_terminal and "COLUMNS" not in os.environ:
        out.width = 100_000  # a file or a pipe gets every column and unbroken lines
    return out


def error_text(exc: BaseException) -> str:
    """The one line ``unitrack`` prints after "error:" for ``exc``."""
    if isinstance(exc, KeyError) and exc.args and type(exc) is KeyError:
        return str(exc.args[0])
    text = str(exc) or type(exc).__name__
    known = (ValueError, KeyError, OSError, ImportError, RuntimeError)
    return text if isinstance(exc, known) else f"{type(exc).__name__}: {text}"


def _number(text: str, kind: type, ok: Callable[[float], bool], wanted: str) -> Any:
    """``text`` read as ``kind``; ArgumentTypeError unless ``ok(value)`` (``wanted`` says it)."""
    try:
        value = kind(text)
    except ValueError:
        noun = "whole number" if kind is int else "number"
        raise argparse.ArgumentTypeError(f"{text!r} is not a {noun}") from None
    if not ok(value):
        raise argparse.ArgumentTypeError(f"{text} is not {wanted}")
    return value


def positive_int(text: str) -> int:
    """An integer >= 1 (``--workers``)."""
    return _number(text, int, lambda v: v >= 1, ">= 1")


def positive_float(text: str) -> float:
    """A finite number > 0 (``--fps``)."""
    return _number(text, float, lambda v: 0 < v < float("inf"), "a positive number")


def non_negative_float(text: str) -> float:
    """A finite number >= 0 (``--step-timeout``, where 0 means no limit)."""
    return _number(text, float, lambda v: 0 <= v < float("inf"), "a number >= 0")


def names(text: str) -> list[str]:
    """Comma-separated names, none empty (``--sequences``)."""
    parts = [part.strip() for part in text.split(",")]
    if not all(parts):
        raise argparse.ArgumentTypeError(f"{text!r} holds an empty name; give names "
                                         "separated by commas, e.g. MOT17-02-FRCNN,MOT17-04-FRCNN")
    return parts


def check_env_id(env_id: str) -> str:
    """The env id, or a ValueError with the closest registered ids."""
    ids = unitrack_env.env_ids()
    if env_id in ids:
        return env_id
    close = difflib.get_close_matches(env_id, ids, n=3, cutoff=0.5)
    hint = f"did you mean {' or '.join(close)}? " if close else ""
    raise ValueError(f"unknown environment '{env_id}'; {hint}`unitrack list` shows all ids")


def env_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """The environment arguments from the command line, checked against the env's options."""
    env_id = check_env_id(args.env)
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


def agent_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """The agent arguments from the command line, checked against the agent's options."""
    return parse_options(agent_class(args.agent), args.agent_arg or [], agent=args.agent)


def print_metrics(console: Console, per_sequence: dict, combined: dict | None, title: str,
                   columns: tuple, fmt: str, fps: dict | None = None, coverage: str = "") -> None:
    """Print metrics as a table fitted to the console, JSON or CSV (``fmt``)."""
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


def env_options(p: argparse.ArgumentParser, *, agent: bool = True) -> None:
    """The options naming an environment and (``agent``) an agent."""
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


def format_option(p: argparse.ArgumentParser) -> None:
    """The ``--format table|json|csv`` option."""
    p.add_argument("--format", choices=("table", "json", "csv"), default="table",
                   help="how to print the metrics (default: a table fitted to the terminal)")
