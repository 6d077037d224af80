"""Per-step time limits: a hung agent becomes a failed sequence, not a run that never ends.

A step lies between two heartbeats of an episode: the reset (with the agent's ``reset``), then
each ``act()`` with ``env.step``. Where the episode plays decides how an overdue step ends:

* in worker processes (``--workers N``), or in one child playing the sequences in order (the
  CLI's default, ``run(isolate=True)``): the parent (:mod:`.pool`) kills the silent process
  and only its sequence fails. Only a separate process can be stopped anywhere (a deadlock or
  a loop in native code that holds the GIL) or survive a segfault; the child costs one
  interpreter start per run, not per sequence (benchmarks/isolation.py);
* in this process (``--in-process``, ``run()``'s default): :class:`StepWatchdog` has the kernel
  send SIGALRM and the handler raises :class:`StepTimeout` in the agent's code. Handlers run
  only between bytecodes or where C code checks for signals, so for a C call that does neither
  the watchdog thread, once it gets the GIL, prints why and exits with status 3 after
  :data:`GRACE` seconds (finished sequences are on disk; the same command resumes).

:class:`StepTimeout` derives from ``BaseException`` so that an agent's ``except Exception``
cannot swallow it.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from types import FrameType, TracebackType

#: The default limit of one step, in seconds (generous: a slow CPU model takes ~1 s).
DEFAULT_STEP_TIMEOUT = 300.0
#: Seconds after the signal before a step that cannot be interrupted ends the process.
GRACE = 30.0


class StepTimeout(BaseException):  # noqa: N818 - it is a stop signal, like KeyboardInterrupt
    """A step took longer than the limit."""


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived: the command stops as for Ctrl-C (finished sequences are kept)."""


@contextlib.contextmanager
def sigterm_stops() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` (on the main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, frame: FrameType | None) -> None:
        raise Terminated

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def timeout_message(seconds: float, frame: int) -> str:
    """The line a timed-out sequence fails with."""
    where = "in the reset" if frame == 0 else f"after frame {frame}"
    return (f"no step finished within {seconds:g} s ({where}): the agent's act() (or the "
            "environment) hung; --step-timeout S changes the limit, 0 disables it")


def limit(seconds: float | None) -> float | None:
    """The limit in seconds, or None for none (None, 0 or a negative number)."""
    return float(seconds) if seconds is not None and seconds > 0 else None


class StepWatchdog:
    """The in-process watchdog: ``start(name)``, ``beat()`` after each step, ``stop()``.

    On the main thread the kernel's interval timer (``setitimer``) sends SIGALRM at the
    deadline: no thread of ours needs the GIL for it, so an agent in C code that holds the
    GIL but checks for signals (a catastrophic regex) is stopped on time. The watchdog
    thread is the fallback (and ends the process after ``grace`` when nothing helps).
    """

    def __init__(self, seconds: float | None, where: str = "", grace: float | None = None
                 ) -> None:
        self.seconds, self.where = limit(seconds), where
        self.grace = GRACE if grace is None else grace
        self.deadline: float | None = None
        self.sequence, self.frame, self.fired = "", 0, 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._signals = False
        self._previous: object = None

    def __enter__(self) -> StepWatchdog:
        if self.seconds is None:
            return self
        self._target = threading.get_ident()
        self._signals = (threading.current_thread() is threading.main_thread()
                         and hasattr(signal, "SIGALRM") and hasattr(signal, "pthread_kill"))
        if self._signals:
            self._previous = signal.signal(signal.SIGALRM, self._on_alarm)
        self._thread = threading.Thread(target=self._watch, name="unitrack-step-watchdog",
                                        daemon=True)
        self._thread.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.deadline = None
        self._arm(0.0)
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        if self._signals:
            signal.signal(signal.SIGALRM, self._previous)  # type: ignore[arg-type]

    def start(self, sequence: str) -> None:
        """A sequence starts (its reset is the first step)."""
        self.sequence, self.frame, self.fired = sequence, 0, 0.0
        if self.seconds is not None:
            self.deadline = time.monotonic() + self.seconds
            self._arm(self.seconds)

    def beat(self, frames: int = 1) -> None:
        """A step ended."""
        self.frame += frames
        self.fired = 0.0
        if self.seconds is not None:
            self.deadline = time.monotonic() + self.seconds
            self._arm(self.seconds)

    def stop(self) -> None:
        """The sequence ended (or failed)."""
        self.deadline = None
        self.fired = 0.0
        self._arm(0.0)

    def _arm(self, seconds: float) -> None:
        """Have the kernel send SIGALRM in ``seconds`` (0: cancel)."""
        if self._signals:
            signal.setitimer(signal.ITIMER_REAL, seconds)

    def _on_alarm(self, signum: int, frame: FrameType | None) -> None:
        deadline = self.deadline
        if deadline is not None and self.seconds is not None:
            left = deadline - time.monotonic()
            if left <= 0:
                self.deadline = None
                raise StepTimeout(timeout_message(self.seconds, self.frame))
            self._arm(left)  # the timer ran a little ahead of the monotonic clock
            return
        if callable(self._previous):  # not ours: the handler we replaced for the run
            self._previous(signum, frame)

    def _watch(self) -> None:
        assert self.seconds is not None
        period = min(1.0, self.seconds / 4)
        while not self._stop.wait(period):
            deadline = self.deadline
            now = time.monotonic()
            if deadline is None or now < deadline:
                continue
            if not self.fired:
                self.fired = now
                if self._signals:
                    signal.pthread_kill(self._target, signal.SIGALRM)
                    continue
            if now - self.fired >= (self.grace if self._signals else 0.0):
                self._give_up()

    def _give_up(self) -> None:
        """The step cannot be interrupted in this process: say why and end the process."""
        sys.stderr.write(
            f"\nerror: sequence '{self.sequence}': {timeout_message(self.seconds or 0, self.frame)}"
            f"; it cannot be interrupted in this process (stuck in native code), so the run "
            f"stops here. Finished sequences are kept{self.where}; run the same command again "
            "to resume, with --workers 2 to play such an agent in worker processes that can "
            "be stopped\n")
        sys.stderr.flush()
        os._exit(3)
