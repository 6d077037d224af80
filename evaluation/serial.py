"""Sequences played in this process, one after the other (``workers=1``).

The counterpart of :mod:`unitrack_env.evaluation.workers`: a failed sequence keeps its
exception (with the agent's traceback) and the next one plays in a fresh environment; a step
longer than the limit fails its sequence (:mod:`unitrack_env.evaluation.watchdog`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym

from unitrack_env.benchmarks.base import Benchmark

from .episode import SequenceRecord, play_episode
from .identity import Stamp
from .watchdog import StepTimeout, StepWatchdog
from .workers import SequenceFailure


def play_here(spec: Any, env: gym.Env, bench: Benchmark, agent_obj: Any, out: Path,
              todo: list[str], stamps: dict[str, Stamp], bar: Any,
              causes: dict[str, BaseException], step_timeout: float | None = None,
              ) -> tuple[dict[str, SequenceRecord], dict[str, str]]:
    """Play ``todo`` in this process; a failed sequence's exception goes into ``causes``.

    A step longer than ``step_timeout`` fails its sequence (:mod:`.watchdog`).
    """
    from .episode import save_episode

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
                   record, _ = play_episode(player, agent_obj, name, benchmark=bench,
                                            on_frame=advance)
               except (ValueError, KeyError, OSError, RuntimeError, StepTimeout) as exc:
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
               save_episode(out, player, record, bench)
               records[name] = record
    finally:
        if player is not env:
            player.close()
    return records, failures
