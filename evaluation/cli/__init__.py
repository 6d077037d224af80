"""The unitrack command line: evaluate trackers on tracking benchmarks, score, render, check.

Every user error (an unknown id or option, bad data, a full disk, an agent that raises) is
reported as one line starting with "error:", printed literally; ``--debug`` adds the
traceback. Finished sequences are always kept: run the same command again to resume.

Commands are registered in one place, :data:`COMMANDS`: a name, the module under
``unitrack_env.evaluation.cli`` that holds it, and its one-line summary. A command's module
defines ``add_arguments(parser)`` and ``run(args, console) -> exit status``, and may define
``EXAMPLES`` (the epilog of its ``--help``) and ``DESCRIPTION`` (else its summary opens its
``--help``). It is imported only when that command runs, so ``unitrack --help`` and a mistyped
command ("did you mean ...?") import none of them. A command's module imports its
implementation (TrackEval, scipy, pandas, torch) inside ``run``, with the measured cost in a
``# lazy:`` comment, so that ``unitrack COMMAND --help`` answers in about 0.25 s, not 1-2 s.
"""

from __future__ import annotations

import argparse
import difflib
import importlib
import sys
import traceback
from collections.abc import Iterable, Sequence
from types import ModuleType

import unitrack_env

from ..run.progress import one_line_warnings
from ..run.watchdog import Terminated, sigterm_stops
from .common import console, error_text

#: Every ``unitrack`` command, in the order of ``unitrack --help``: name -> (module, summary).
COMMANDS: dict[str, tuple[str, str]] = {
    "evaluate": ("evaluate", "run an agent on every sequence of an environment and score it"),
    "score": ("score", "score a folder of result files in the official format"),
    "render": ("render", "write a video of an agent's tracks on one sequence"),
    "scorecard": ("scorecard", "play every task's UniTrack head with each appearance model and "
                  "draw the paper's table and radar chart"),
    "list": ("listing", "list environments and agents"),
    "doctor": ("doctor", "check that this environment can run and score every task (exit "
               "status 1 on a problem, with the fix)"),
    "cache": ("cache", "inspect, prune or clear the feature cache"),
    "events": ("events", "list a run's per-frame error events (ID switches, misses, false "
               "positives, ...; computed from its result files if the run predates them)"),
    "compare": ("compare", "compare two runs: per-sequence and combined metrics, the paired "
                "difference and its 95% interval (paired block jackknife)"),
    "report": ("report", "write a self-contained HTML report of runs (or a scorecard folder): "
               "metrics, error timelines, thumbnails of ID switches and misses"),
    "plot": ("plot", "draw the success and precision plots (and normalized precision where "
             "the benchmark has it) of SOT runs, all runs on one figure, as PNG and SVG"),
    "tune": ("tune", "search a head's options for the best value of a metric on a tuning split "
             "(on Optuna, resumable), then compare the best setting with the defaults on a "
             "validation split"),
}


def command_module(name: str) -> ModuleType:
    """The module of command ``name`` (imported now)."""
    return importlib.import_module(f".{COMMANDS[name][0]}", __name__)


def build_parser(commands: Iterable[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser of ``unitrack``, with the options of ``commands`` (default: all).

    Every command is listed; only those in ``commands`` have their module imported and
    their options added.
    """
    parser = argparse.ArgumentParser(
        prog="unitrack", description=__doc__.split("\n")[0],
        epilog="`unitrack COMMAND --help` shows each command's options and examples.",
    )
    parser.add_argument("--version", action="version",
                        version=f"unitrack-env {unitrack_env.__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback of an error")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    chosen = set(COMMANDS if commands is None else commands)
    for name, (_, summary) in COMMANDS.items():
        help_text = summary.replace("%", "%%")  # argparse %-formats a help, not a description
        if name not in chosen:
            sub.add_parser(name, help=help_text, add_help=False)
            continue
        module = command_module(name)
        command = sub.add_parser(name, help=help_text,
                                 description=getattr(module, "DESCRIPTION", summary),
                                 epilog=getattr(module, "EXAMPLES", None),
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
        module.add_arguments(command)
    return parser


def _command_in(argv: Sequence[str], parser: argparse.ArgumentParser) -> str | None:
    """The command named in ``argv`` (its first word that is not an option), or None.

    A word that is no command ends here, with the closest commands ("did you mean").
    """
    word = next((a for a in argv if not a.startswith("-")), None)
    if word is None or word in COMMANDS:
        return word
    close = difflib.get_close_matches(word, COMMANDS, n=3, cutoff=0.5)
    hint = f"; did you mean {' or '.join(close)}?" if close else ""
    parser.error(f"unknown command '{word}'{hint} (`unitrack --help` lists the commands)")
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``unitrack`` command; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    name = _command_in(argv, build_parser(()))
    args = build_parser([name] if name else ()).parse_args(argv)
    out = console()
    try:
        with one_line_warnings(), sigterm_stops():
            return command_module(args.command).run(args, out)
    except KeyboardInterrupt as stop:  # Ctrl-C, or SIGTERM (Terminated): exit 130 or 143
        what = "terminated (SIGTERM)" if isinstance(stop, Terminated) else "interrupted"
        console(stderr=True).print(f"{what}: finished sequences are kept; run the same "
                                   "command again to resume", markup=False)
        return 143 if isinstance(stop, Terminated) else 130
    except Exception as exc:
        errors = console(stderr=True)
        if args.debug:
            errors.print("".join(traceback.format_exception(exc)), markup=False)
        # lazy: start-up cost (run.runner loads scipy and TrackEval: +0.8 s on every `unitrack`)
        from ..run.runner import RunFailed

        errors.print(f"error: {error_text(exc)}", markup=False)
        if not args.debug:
            errors.print("(--debug shows the traceback)", markup=False, style="dim")
        return 1 if isinstance(exc, RunFailed) else 2
