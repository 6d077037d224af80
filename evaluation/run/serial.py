"""Sequences played one after the other (``workers=1``), here or in one supervised child.

The counterpart of :mod:`unitrack_env.evaluation.run.workers`: a failed sequence keeps its
exception (with the agent's traceback) and the next one plays in a fresh environment; a step
longer than the limit fails its sequence (:mod:`unitrack_env.evaluation.run.watchdog`).
:func:`play_isolated` plays the same way in one child process that the parent watches (the
CLI's default), so that a step stuck in native code, a crash or a ``close()`` that never
returns ends only what it was doing.
"""

from __future__ import annotations

import importlib
import traceback
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym

from unitrack_env.agents.base import close_agent
from unitrack_env.benchmarks.base import Benchmark

from .episode import SequenceRecord, play_repetitions, save_episode
from .identity import Stamp
from .pool import SupervisedPool, WorkerDied, WorkerTimedOut
from .watchdog import StepTimeout, StepWatchdog, limit
from .workers import RemoteTraceback, SequenceFailure, worker_init

#: The child's environment and agent, kept from one sequence to the next (as in this process).
_KEPT: dict[str, Any] = {}
#: The errors that fail a sequence and let the next one play (any other stops the run).
SEQUENCE_ERRORS = (ValueError, KeyError, OSError, RuntimeError)


def play_here(spec: Any, env: gym.Env, bench: Benchmark, agent_obj: Any, out: Path,
              todo: list[str], stamps: dict[str, Stamp], bar: Any,
              causes: dict[str, BaseException], step_timeout: float | None = None,
              ) -> tuple[dict[str, SequenceRecord], dict[str, str]]:
    """Play ``todo`` in this process; a failed sequence's exception goes into ``causes``.

    A step longer than ``step_timeout`` fails its sequence (:mod:`.watchdog`).
    """
    records: dict[str, SequenceRecord] = {}
    failures: dict[str, str] = {}
    player = env
    watchdog = StepWatchdog(step_timeout, where=f" in {out}")

    def advance() -> None:
        watchdog.beat()
        bar.advance()

    try:
        with watchdog:
            for name in todo:
               bar.start_sequence(name)
               watchdog.start(name)
               try:
                   record, played = play_repetitions(player, agent_obj, name, benchmark=bench,
                                                     repeats=spec.repeats, on_frame=advance)
               except (*SEQUENCE_ERRORS, StepTimeout) as exc:
                   watchdog.stop()
                   failures[name], causes[name] = SequenceFailure.describe(exc), exc
                   # A reset that raised leaves Gymnasium's checker wrapper without its first
                   # observation; the next episode gets a fresh environment.
                   if player is not env:
                       player.close()
                   player = spec.make_env()
                   continue
               watchdog.stop()
               stamps[name].apply(record)
               save_episode(out, player, record, bench, played)
               records[name] = record
    finally:
        if player is not env:
            player.close()
    return records, failures


def _play_kept(spec: Any, out: str, sequence: str | None, stamp: Stamp | None, entry: str,
               beat: Any) -> tuple[Any, ...]:
    """Child: play ``sequence`` with the kept agent (made on the first call) and save it.

    ``sequence`` None closes the agent (the last task). ``entry``: the module of the env's
    entry point, imported first when the id is not registered here (an id registered in
    the parent at run time: its package registers it). Returns ``("ok", record)``,
    ``("error", message, traceback)``, ``("unmade", message, traceback)`` or ``("closed",)``.
    """
    if sequence is None:
        beat(0)  # close() is timed like a step
        agent, env = _KEPT.pop("agent", None), _KEPT.pop("env", None)
        if agent is not None:
            close_agent(agent)
        if env is not None:
            env.close()
        return ("closed",)
    if "agent" not in _KEPT:
        try:
            if entry and spec.env_id not in gym.registry:
                importlib.import_module(entry)
            _KEPT["env"] = spec.make_env()
            _KEPT["agent"] = spec.make_agent()
        except Exception as exc:
            return "unmade", SequenceFailure.describe(exc), traceback.format_exc()
    env = _KEPT["env"]
    beat(0)  # the episode starts: the parent's step clock runs from here
    try:
        record, played = play_repetitions(env, _KEPT["agent"], sequence,
                                          benchmark=env.unwrapped.scoring,
                                          repeats=spec.repeats, on_frame=beat)
    except SEQUENCE_ERRORS as exc:
        failure = ("error", SequenceFailure.describe(exc), traceback.format_exc())
        env.close()  # the next episode gets a fresh environment, as in this process
        _KEPT["env"] = spec.make_env()
        return failure
    assert stamp is not None
    stamp.apply(record)
    save_episode(Path(out), env, record, env.unwrapped.scoring, played)
    return "ok", record.to_json()


def play_isolated(spec: Any, out: Path, todo: list[str], stamps: dict[str, Stamp], bar: Any,
                  causes: dict[str, BaseException], step_timeout: float | None = None,
                  ) -> tuple[dict[str, SequenceRecord], dict[str, str]]:
    """Play ``todo`` in order in one supervised child process; as :func:`play_here`.

    The child makes its own environment and agent once and keeps them (the caller's copy,
    made to check the options before the first frame, neither plays nor is closed); a step
    longer than ``step_timeout`` (even in C code holding the GIL) or a crash kills it, fails
    only that sequence (the signal named), and a fresh child plays the rest. ``close()``
    runs last in the child, timed like a step: one that never returns is stopped with a
    warning, the results kept.
    """
    records: dict[str, SequenceRecord] = {}
    failures: dict[str, str] = {}
    if not todo:  # all kept (a resumed run): no child, no copy of the agent to close
        return records, failures
    playing: list[str | None] = [None]

    def on_beat(name: str | None, frames: int) -> None:
        if name is not None and name != playing[0]:
            playing[0] = name
            bar.start_sequence(name)
        bar.advance(frames)

    entry = gym.spec(spec.env_id).entry_point
    entry = entry.partition(":")[0] if isinstance(entry, str) else ""
    with SupervisedPool(1, 0, step_timeout, init=worker_init()) as pool:  # 0: torch defaults
        played = pool.run(_play_kept, [*todo, None],
                          lambda name: (spec, str(out), name, stamps.get(name or ""), entry),
                          on_beat=on_beat)
        for name, outcome in played:
            if name is None:
                _closed(spec, outcome, step_timeout)
            elif isinstance(outcome, BaseException):
                if not isinstance(outcome, (RuntimeError, ValueError, KeyError)):
                    raise outcome  # OutputError (a full disk), an agent's TypeError: stop
                failures[name] = str(outcome)
            elif outcome[0] == "ok":
                records[name] = SequenceRecord.from_json(outcome[1])
            elif outcome[0] == "unmade":  # as when the agent fails to build in this process
                raise RuntimeError(outcome[1]) from RemoteTraceback(outcome[2])
            else:
                failures[name], causes[name] = outcome[1], RemoteTraceback(outcome[2])
    return records, failures


def _closed(spec: Any, outcome: Any, step_timeout: float | None) -> None:
    """The outcome of the agent's ``close()`` in the child; a hang or a crash is a warning.

    Every sequence is already saved; an exception close() raised is raised, as in this process.
    """
    if isinstance(outcome, WorkerTimedOut):
        warnings.warn(f"agent '{spec.agent}': close() did not return within "
                      f"{limit(step_timeout):g} s; its process was stopped (the results are "
                      "kept)", RuntimeWarning, stacklevel=2)
    elif isinstance(outcome, WorkerDied):
        warnings.warn(f"agent '{spec.agent}': close() did not end: "
                      f"{str(outcome).replace('playing it', 'closing it')} (the results are "
                      "kept)", RuntimeWarning, stacklevel=2)
    elif isinstance(outcome, BaseException):
        raise outcome
