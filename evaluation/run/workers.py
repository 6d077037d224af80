"""Sequences played in parallel worker processes, robust to failures on either side.

A failing sequence comes back as a one-line message; a dead or hung worker fails only its
sequence; workers exit when their parent dies; each gets ``cpu_count // workers`` threads.
"""

from __future__ import annotations

import ast
import functools
import inspect
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable
from multiprocessing import current_process
from pathlib import Path
from typing import Any

from unitrack_env.agents.base import close_agent
from unitrack_env.errors import CheckpointError, DataFormatError, InvalidActionError

from .episode import OutputError, SequenceRecord, play_repetitions, save_episode
from .pool import CLOSING, SupervisedPool
from .progress import show_warnings_once, shown_warnings

#: Seconds between a worker's checks that its parent is alive.
WATCHDOG_PERIOD = 0.5


class SequenceFailure:
    """How a failed sequence is described to the user: one line, the real message."""

    @staticmethod
    def describe(exc: BaseException) -> str:
        """``message`` for the project's own errors, ``Type: message`` otherwise."""
        if isinstance(exc, (DataFormatError, CheckpointError, InvalidActionError)):
            return str(exc)
        if isinstance(exc, RuntimeError) and str(exc).startswith("agent '"):
            return str(exc)
        if isinstance(exc, KeyError) and exc.args:
            return str(exc.args[0])
        if type(exc).__name__ == "StepTimeout":
            return str(exc)
        return f"{type(exc).__name__}: {exc}"


class RemoteTraceback(Exception):  # noqa: N818 - it carries text, it is never raised
    """The traceback of an error in a child process, as text.

    The ``__cause__`` of a failure, so that ``--debug`` shows the agent's own lines.
    """

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self.text = text

    def __str__(self) -> str:
        return f"\n(in the child process that played it)\n{self.text}"


def _watch_parent(parent: int) -> None:
    def watch() -> None:
        while True:
            if os.getppid() != parent:
                os._exit(1)
            time.sleep(WATCHDOG_PERIOD)

    threading.Thread(target=watch, name="unitrack-parent-watchdog", daemon=True).start()


def init_worker(parent: int, threads: int, shown: Iterable[str] = ()) -> None:
    """Set up a worker process: ignore Ctrl-C, die with the parent, one-line warnings.

    ``shown``: warnings the parent gave already (:func:`worker_init` passes them).
    """
    # Ctrl-C reaches the whole process group; the parent handles it (keeps finished
    # sequences, stops the pool), so the workers must not die mid-write on their own.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _watch_parent(parent)
    show_warnings_once(set(shown))  # the worker's own warnings, as one line, each once
    if threads:
        import torch  # lazy: start-up cost (+1.4 s; agents without a network never load torch)

        torch.set_num_threads(threads)


def worker_init() -> Callable[[int, int], None]:
    """The ``init`` of a pool started now: :func:`init_worker`, with the warnings shown so far."""
    return functools.partial(init_worker, shown=shown_warnings())


def _play_one(spec: Any, out: str, sequence: str, stamp: Any,
              beat: Any = None) -> tuple[str, Any]:
    """Worker: play one sequence and save it; ``("ok", record)`` or ``("error", message)``.

    ``beat`` is called after every step (the parent's progress bar and step watchdog).
    """
    env = agent = None
    try:
        env = spec.make_env()
        agent = spec.make_agent()
        bench = env.unwrapped.scoring
        if beat is not None:
            beat(0)  # the episode starts: the parent's step clock runs from here
        record, played = play_repetitions(env, agent, sequence, benchmark=bench,
                                          repeats=spec.repeats, on_frame=beat)
        stamp.apply(record)  # an identity.Stamp
        save_episode(Path(out), env, record, bench, played)
        if beat is not None:
            beat(CLOSING)  # a close() that hangs is named as such
        return "ok", record.to_json()
    except OutputError:
        raise
    except Exception as exc:
        return "error", SequenceFailure.describe(exc)
    finally:
        if agent is not None:
            close_agent(agent)
        if env is not None:
            env.close()


def refuse_unguarded_script() -> None:
    """Refuse to start worker processes from a script's unguarded top level.

    Spawned workers re-import the script, re-running its top-level code (a second
    ``run(..., overwrite=True)`` could clear the folder being written).
    """
    message = ("put the code that calls run(..., workers=N) or scorecard(..., workers=N) under "
               "'if __name__ == \"__main__\":' — worker processes import {} and would run it "
               "again")
    if getattr(current_process(), "_inheriting", False):  # a worker importing the script
        raise RuntimeError(message.format("the script"))
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    frame, top = inspect.currentframe(), None
    while frame is not None:  # the script's own top-level statement that led here
        if frame.f_globals.get("__name__") == "__main__" and frame.f_code.co_name == "<module>":
            top = frame
        frame = frame.f_back
    if path is None or top is None or not Path(path).is_file():
        return
    if Path(top.f_code.co_filename).resolve() != Path(path).resolve():
        return  # a script run by runpy under another main module: that one is re-imported
    try:
        tree = ast.parse(Path(path).read_text(encoding="utf-8"))
    except (OSError, SyntaxError, ValueError):
        return
    line = top.f_lineno
    guarded = any(isinstance(node, ast.If) and "__main__" in ast.unparse(node.test)
                  and node.lineno <= line <= (node.end_lineno or node.lineno)
                  for node in tree.body)
    if not guarded:
        raise RuntimeError(message.format(f"{path} (line {line})"))


def play_in_workers(spec: Any, out: Path, todo: list[str], stamps: dict[str, Any],
                    lengths: dict[str, int], workers: int, bar: Any,
                    step_timeout: float | None = None) -> tuple[dict[str, Any], dict[str, str]]:
    """Play ``todo`` in ``workers`` supervised processes; return (records, failures).

    A worker that dies or overruns ``step_timeout`` fails only the sequence it was playing
    (:mod:`unitrack_env.evaluation.run.pool`).
    """
    records: dict[str, SequenceRecord] = {}
    failures: dict[str, str] = {}
    threads = max(1, (os.cpu_count() or 1) // workers)
    with SupervisedPool(min(workers, len(todo)), threads, step_timeout,
                        init=worker_init()) as pool:
        played = pool.run(_play_one, todo, lambda s: (spec, str(out), s, stamps[s]),
                          on_beat=lambda s, frames: bar.advance(frames))
        for name, outcome in played:
            if isinstance(outcome, BaseException):
                if not isinstance(outcome, (RuntimeError, ValueError, KeyError)):
                    raise outcome  # OutputError (a full disk): stop, as in this process
                failures[name] = str(outcome)
                continue
            status, payload = outcome
            if status == "ok":
                records[name] = SequenceRecord.from_json(payload)
            else:
                failures[name] = payload
    return records, failures
