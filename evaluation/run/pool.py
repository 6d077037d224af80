"""Worker processes supervised one by one: the parent knows who plays what, and for how long.

``concurrent.futures``' process pool cannot say which process ran which task: when one dies,
every task in flight fails with ``BrokenProcessPool``, and a task that never returns blocks it
for ever. Here each spawned worker has its own pipe, runs one task at a time and sends a
heartbeat after each step. So the parent blames a death only on that worker's task (naming the
signal: :func:`describe_exit`) and starts a fresh worker for the rest, and kills a worker whose
task sent no heartbeat for ``step_timeout`` seconds (a hang even inside a C call). The clock
starts at the task's first heartbeat: imports and building the env and agent are not steps.
"""

from __future__ import annotations

import os
import pickle
import signal
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from multiprocessing import get_context
from multiprocessing.connection import Connection, wait
from typing import Any

from .watchdog import limit, timeout_message

#: A task's heartbeat that says its work is saved and the agent's close() runs (timed too).
CLOSING = "closing"


class WorkerDied(RuntimeError):
    """The worker process running a task ended without an answer."""


class WorkerTimedOut(RuntimeError):
    """A task sent no heartbeat for longer than the step limit; its worker was killed."""


#: What a worker's death by signal most likely means.
SIGNAL_CAUSES = {
    "SIGKILL": "usually the out-of-memory killer, which the system log and dmesg name; or a "
               "kill -9",
    "SIGSEGV": "a segmentation fault: a crash in native code such as a C extension or a GPU "
               "driver",
    "SIGBUS": "a bus error: a crash in native code, or a memory-mapped file that shrank",
    "SIGABRT": "native code called abort(), e.g. a failed assertion in a C/C++ library",
    "SIGFPE": "an arithmetic fault in native code",
    "SIGTERM": "someone terminated it",
}


def describe_exit(exitcode: int | None) -> str:
    """Why a worker ended, in words: the signal by name, or the exit status."""
    if exitcode is None:
        return "the worker process playing it stopped answering"
    if exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        cause = SIGNAL_CAUSES.get(name, "a signal from outside")
        return f"the worker process playing it was killed by {name} ({cause})"
    return (f"the worker process playing it exited with status {exitcode} (the agent or a "
            "library called exit)")


def _worker_main(conn: Connection, parent: int, threads: int,
                 init: Callable[[int, int], None]) -> None:
    """A worker: ``init(parent, threads)``, then run tasks from the pipe until told to stop.

    A heartbeat goes back after each step.
    """
    init(parent, threads)
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        number, fn, args = task

        def beat(frames: int = 1, number: int = number) -> None:
            _send(conn, ("beat", number, frames))

        try:
            answer: tuple[Any, ...] = ("ok", number, fn(*args, beat))
        except BaseException as exc:  # noqa: BLE001 - every failure goes back to the parent
            answer = ("raised", number, exc)
        try:
            _send(conn, answer)
        except (pickle.PicklingError, TypeError, AttributeError) as exc:
            _send(conn, ("raised", number, RuntimeError(f"the task's answer cannot be sent "
                                                        f"back: {type(exc).__name__}: {exc}")))


def _send(conn: Connection, message: tuple[Any, ...]) -> None:
    """Send to the parent; when it is gone (killed, terminated), end this worker quietly."""
    try:
        conn.send(message)
    except OSError:  # BrokenPipeError: no one is left to read the answer or a traceback
        os._exit(1)


@dataclass
class _Worker:
    process: Any
    conn: Connection
    number: int | None = None
    item: Any = None
    beat: float = 0.0
    frames: int = 0
    started: bool = False  # the task's first heartbeat came (start-up is not a step)
    closing: bool = False  # the task's work is saved; the agent's close() runs


class SupervisedPool:
    """``workers`` spawned processes; :meth:`run` yields ``(item, result or exception)``.

    Each process first calls ``init(parent pid, threads)``
    (:func:`~unitrack_env.evaluation.run.workers.init_worker`; passed in, so that this module does
    not import the one that uses it).
    """

    def __init__(self, workers: int, threads: int, step_timeout: float | None = None, *,
                 init: Callable[[int, int], None]) -> None:
        self.size, self.threads, self.init = max(1, workers), threads, init
        self.step_timeout = limit(step_timeout)
        self.context = get_context("spawn")
        self.workers: list[_Worker] = []

    def _spawn(self) -> _Worker:
        mine, theirs = self.context.Pipe()
        process = self.context.Process(target=_worker_main, name="unitrack-worker",
                                       args=(theirs, os.getpid(), self.threads, self.init))
        process.start()
        theirs.close()
        worker = _Worker(process, mine)
        self.workers.append(worker)
        return worker

    def _retire(self, worker: _Worker, kill: bool = False) -> None:
        if kill:
            worker.process.kill()
        worker.process.join(timeout=10)
        worker.conn.close()
        self.workers.remove(worker)

    def run(self, fn: Callable[..., Any], items: Iterable[Any], args: Callable[[Any], tuple],
            on_beat: Callable[[Any, int], None] | None = None) -> Iterator[tuple[Any, Any]]:
        """Call ``fn(*args(item), beat)`` in the workers; yield each item with its outcome."""
        queue = deque(enumerate(items))
        while queue or any(w.number is not None for w in self.workers):
            while queue and len(self.workers) < self.size:
                self._spawn()
            for worker in list(self.workers):
                if worker.number is None and not worker.process.is_alive():
                    self._retire(worker)  # died idle, after its last answer: blame no one
                elif worker.number is None and queue:
                    worker.number, worker.item = queue.popleft()
                    worker.beat, worker.frames, worker.started = time.monotonic(), 0, False
                    worker.closing = False
                    worker.conn.send((worker.number, fn, args(worker.item)))
            if any(w.number is not None for w in self.workers):
                yield from self._wait(on_beat)

    def _wait(self, on_beat: Callable[[Any, int], None] | None) -> Iterator[tuple[Any, Any]]:
        busy = [w for w in self.workers if w.number is not None]
        timeout = None
        timed = [w.beat for w in busy if w.started]
        if self.step_timeout is not None and timed:
            timeout = max(0.0, min(timed) + self.step_timeout - time.monotonic())
        ready = set(wait([w.conn for w in busy] + [w.process.sentinel for w in busy],
                         timeout=timeout))
        for worker in busy:
            if worker.conn in ready or worker.process.sentinel in ready:
                yield from self._serve(worker, on_beat)
            elif (self.step_timeout is not None and worker.started
                  and time.monotonic() - worker.beat >= self.step_timeout):
                item = worker.item
                self._retire(worker, kill=True)
                yield item, WorkerTimedOut(
                    (f"the agent's close() did not return within {self.step_timeout:g} s "
                     "after the sequence was saved (run the same command again to keep it)"
                     if worker.closing else timeout_message(self.step_timeout, worker.frames))
                    + "; its worker process was stopped")

    def _serve(self, worker: _Worker, on_beat: Callable[[Any, int], None] | None
               ) -> Iterator[tuple[Any, Any]]:
        """Read what a worker sent (heartbeats, its answer), or report its death."""
        try:
            while worker.number is not None and worker.conn.poll():
                kind, number, payload = worker.conn.recv()
                if kind == "beat" and payload == CLOSING:
                    worker.beat, worker.closing = time.monotonic(), True
                    continue
                if kind == "beat":
                    worker.beat, worker.frames = time.monotonic(), worker.frames + payload
                    worker.started = True
                    if on_beat is not None:
                        on_beat(worker.item, payload)
                    continue
                item, worker.number, worker.item = worker.item, None, None
                yield item, payload
        except (EOFError, OSError):  # the pipe closed: the process ends (or is ended)
            worker.process.join(timeout=5)
            if worker.process.is_alive():
                worker.process.kill()
                worker.process.join(timeout=5)
        except Exception as exc:  # an answer that cannot be unpickled here
            item, worker.number, worker.item = worker.item, None, None
            yield item, RuntimeError(f"the answer cannot be read: {type(exc).__name__}: {exc}")
        if worker.number is not None and not worker.process.is_alive():
            item = worker.item
            self._retire(worker)
            yield item, WorkerDied(describe_exit(worker.process.exitcode))

    def close(self, *, kill: bool = False) -> None:
        """Stop every worker (``kill``: at once, else once they finish their task)."""
        for worker in list(self.workers):
            if not kill:
                try:
                    worker.conn.send(None)
                except OSError:
                    pass
            self._retire(worker, kill=kill)

    def __enter__(self) -> SupervisedPool:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        self.close(kill=exc_type is not None)
