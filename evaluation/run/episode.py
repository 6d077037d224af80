"""The one episode loop of the project, and the record of a played episode.

The runner, video rendering and the regression helpers all play through :func:`play_episode`.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym

from unitrack_env.benchmarks.base import Benchmark
from unitrack_env.io import atomic_write_text
from unitrack_env.provenance import recording_runtimes

from .identity import result_digest


@dataclass
class SequenceRecord:
    """What one finished episode left behind."""

    sequence: str
    frames: int
    seconds: float
    digest: str
    episode_return: float
    inputs: str = ""
    results: str = ""
    runtimes: list[str] | None = None
    """What computed the appearance features (:mod:`unitrack_env.provenance`): ``[]`` for an
    appearance-free agent, None in records written before it was kept."""
    code: dict[str, str] | None = None
    """The agent's code when it was played: ``{file: content digest}``
    (:func:`~unitrack_env.evaluation.run.agent_code.code_manifest`); None until the run's stamp
    is applied."""
    data: str = ""
    """Fingerprint of the sequence's data files when it was played (ground truth and
    annotations by content, frames by name and size; :mod:`.integrity`); "" in older records."""

    @property
    def fps(self) -> float:
        """Frames per second of the whole episode (env + agent)."""
        return self.frames / self.seconds if self.seconds > 0 else float("inf")

    def to_json(self) -> dict[str, Any]:
        """The stored form (with the FPS for readers)."""
        return asdict(self) | {"fps": self.fps}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> SequenceRecord:
        """Read a stored record (unknown keys ignored)."""
        names = cls.__dataclass_fields__
        return cls(**{key: value for key, value in data.items() if key in names})


class OutputError(OSError):
    """The output folder cannot be written (read-only, full, failing disk)."""


def save_episode(out: Path, env: gym.Env, record: SequenceRecord,
                 benchmark: Benchmark, played: Played | None = None) -> None:
    """Write the finished episode's results, then its record (the record marks it done).

    ``played``: every repetition's results and times (:func:`play_repetitions`), written by
    the benchmark's ``write_repetitions``; None: the environment's last episode, by ``write``.
    """
    base = env.unwrapped
    try:
        if played is None:
            benchmark.write(out / "data", record.sequence, recorded_results(env))
        else:
            benchmark.write_repetitions(out / "data", record.sequence, played.runs,
                                        played.seconds)
        record.results = result_digest(out / "data", record.sequence, base.sequence_names)
        atomic_write_text(out / "sequences" / f"{record.sequence}.json",
                          json.dumps(record.to_json(), indent=2))
    except OSError as exc:
        raise OutputError(exc.errno, f"cannot write the results of '{record.sequence}' to "
                                     f"{exc.filename or out}: {exc.strerror or exc}; finished "
                                     "sequences are kept") from exc


def recorded_results(env: gym.Env) -> Any:
    """What the environment recorded in its episode, in its benchmark's ``results`` form."""
    return env.unwrapped.episode_results()


def play_episode(
    env: gym.Env,
    agent: Any,
    sequence: str,
    *,
    benchmark: Benchmark | None = None,
    on_frame: Callable[[], None] | None = None,
    on_reset: Callable[[dict[str, Any]], None] | None = None,
    frame_seconds: list[float] | None = None,
) -> tuple[SequenceRecord, dict[str, Any]]:
    """Play one sequence; return its record and the final info (results stay in the env).

    The record's digest is ``benchmark``'s digest of the recorded results (without a
    benchmark, the environment's own). ``on_reset`` gets the reset info; ``on_frame`` is
    called after every step; ``frame_seconds``, when given, gets the agent's seconds for each
    frame (its ``act``; the first frame's includes its ``reset``: a tracker's init and update
    times, as the got10k toolkit records them).
    """
    start = time.perf_counter()
    with recording_runtimes() as runtimes:
        observation, info = env.reset(options={"sequence": sequence})
        if on_reset is not None:
            on_reset(info)
        tick = time.perf_counter()
        agent.reset(observation, info)
        frames, total = 0, 0.0
        terminated = truncated = False
        while not (terminated or truncated):
            try:
                action = agent.act(observation)
                if frame_seconds is not None:
                    frame_seconds.append(time.perf_counter() - tick)
            except Exception as exc:
                raise RuntimeError(
                    f"agent '{getattr(agent, 'name', '') or type(agent).__name__}' failed on "
                    f"sequence '{sequence}', frame {info.get('frame_index')}: "
                    f"{type(exc).__name__}: {exc}"
                ) from exc
            observation, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            frames += 1
            if on_frame is not None:
                on_frame()
            tick = time.perf_counter()
    seconds = time.perf_counter() - start
    digest = (benchmark.digest(recorded_results(env)) if benchmark is not None
              else env.unwrapped.episode_digest())
    return SequenceRecord(sequence, frames, seconds, digest, total,
                          runtimes=sorted(runtimes)), info


@dataclass
class Played:
    """Every repetition of one sequence: results (the benchmark's form) and per-frame times."""

    runs: list[Any]
    seconds: list[list[float]]


def play_repetitions(env: gym.Env, agent: Any, sequence: str, *, benchmark: Benchmark,
                     repeats: int = 1, on_frame: Callable[[], None] | None = None,
                     ) -> tuple[SequenceRecord, Played]:
    """Play ``sequence`` ``repeats`` times in a row with the same agent.

    Returns the first repetition's record (what a run without repetitions records) and
    every repetition's results and per-frame agent times. An agent whose episodes are
    deterministic gives equal repetitions; one with randomness it does not reset gives
    different ones (the spread ``unitrack evaluate --repeats`` reports).
    """
    played = Played([], [])
    record = None
    for _ in range(repeats):
        seconds: list[float] = []
        this, _ = play_episode(env, agent, sequence, benchmark=benchmark, on_frame=on_frame,
                               frame_seconds=seconds)
        record = record or this
        played.runs.append(recorded_results(env))
        played.seconds.append(seconds)
    assert record is not None, "repeats must be at least 1"
    return record, played
