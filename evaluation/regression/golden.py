"""Golden episode records: what an agent scored on one episode, and how to compare."""

from __future__ import annotations

import fnmatch
import json
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym

import unitrack_env
from unitrack_env.agents.base import close_agent, make_agent
from unitrack_env.io import atomic_write_text

from ..run.episode import play_episode
from ..run.identity import option_changes

#: Default absolute tolerance on every metric (metrics are fractions or counts).
DEFAULT_TOLERANCE = 1e-6
#: Record format version; bump when the fields change.
FORMAT_VERSION = 1


@dataclass
class EpisodeRecord:
    """One episode's outcome, as stored in a golden file.

    ``env_kwargs`` exclude ``root`` (machine-specific); the caller supplies the data.
    """

    env_id: str
    sequence: str
    agent: str
    metrics: dict[str, float]
    digest: str
    frames: int
    agent_kwargs: dict[str, Any] = field(default_factory=dict)
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    format_version: int = FORMAT_VERSION

    def to_json(self) -> str:
        """Serialise (sorted keys, stable for version control)."""
        return json.dumps(asdict(self), indent=2, sort_keys=True) + "\n"

    @classmethod
    def load(cls, path: str | os.PathLike) -> EpisodeRecord:
        """Read a golden file."""
        data = json.loads(Path(path).read_text())
        return cls(**data)


class GoldenMismatch(AssertionError):
    """A replayed episode differs from its golden record beyond the tolerance."""


def record_episode(
    env_id: str,
    agent: str,
    sequence: str,
    *,
    env_kwargs: dict[str, Any] | None = None,
    agent_kwargs: dict[str, Any] | None = None,
) -> EpisodeRecord:
    """Play one episode and return its record.

    The metrics are the env's final ``info``; the action digest is the env's benchmark's
    digest of the recorded results.
    """
    unitrack_env.register_all()
    env_kwargs = dict(env_kwargs or {})
    agent_kwargs = dict(agent_kwargs or {})
    env = gym.make(env_id, **env_kwargs)
    tracker = make_agent(agent, **agent_kwargs)
    try:
        bench = getattr(env.unwrapped, "scoring", None)
        record, info = play_episode(env, tracker, sequence, benchmark=bench)
    finally:
        close_agent(tracker)
        env.close()
    if "metrics" not in info:
        raise ValueError(f"{env_id} sequence '{sequence}' has no ground truth: nothing to record")
    stored_kwargs = {k: v for k, v in env_kwargs.items() if k != "root"}
    return EpisodeRecord(
        env_id=env_id, sequence=sequence, agent=agent,
        metrics={k: float(v) for k, v in info["metrics"].items()},
        digest=record.digest, frames=record.frames,
        agent_kwargs=json.loads(json.dumps(agent_kwargs, default=str)),
        env_kwargs=json.loads(json.dumps(stored_kwargs, default=str)),
    )


def metric_tolerance(tolerance: float | dict[str, float], name: str) -> float:
    """The absolute tolerance of metric ``name``.

    ``tolerance`` is a number, or a dict of names or ``fnmatch`` patterns: an exact name wins,
    then the first matching pattern, then ``"*"``, else :data:`DEFAULT_TOLERANCE`.
    """
    if not isinstance(tolerance, dict):
        return float(tolerance)
    if name in tolerance:
        return float(tolerance[name])
    for pattern, value in tolerance.items():
        if fnmatch.fnmatchcase(name, pattern):
            return float(value)
    return DEFAULT_TOLERANCE


def compare_records(
    golden: EpisodeRecord,
    actual: EpisodeRecord,
    *,
    tolerance: float | dict[str, float] = DEFAULT_TOLERANCE,
    metrics: list[str] | None = None,
    strict_actions: bool = False,
) -> list[str]:
    """Human-readable differences of ``actual`` from ``golden`` (empty when it still matches).

    ``strict_actions`` also fails on a changed action digest with unchanged metrics.
    """
    problems: list[str] = []
    if golden.frames != actual.frames:
        problems.append(f"frames: golden {golden.frames}, now {actual.frames}")
    names = metrics if metrics is not None else sorted(golden.metrics)
    rows = []
    for name in names:
        if name not in golden.metrics:
            problems.append(f"metric '{name}' is not in the golden file")
            continue
        if name not in actual.metrics:
            problems.append(f"metric '{name}' is missing from the replayed episode")
            continue
        tol = metric_tolerance(tolerance, name)
        old, new = golden.metrics[name], actual.metrics[name]
        same = (math.isnan(old) and math.isnan(new)) or abs(new - old) <= tol
        if not same:
            rows.append(f"  {name:<10} golden {old:>12.6f}   now {new:>12.6f}   "
                        f"change {new - old:+.6f} (tolerance {tol:g})")
    if rows:
        problems.append("metrics moved beyond tolerance:\n" + "\n".join(rows))
    if strict_actions and golden.digest != actual.digest:
        problems.append(f"action digest changed: golden {golden.digest[:16]}..., "
                        f"now {actual.digest[:16]}...")
    return problems


def check_episode(
    env_id: str,
    agent: str,
    sequence: str,
    golden: str | os.PathLike,
    *,
    env_kwargs: dict[str, Any] | None = None,
    agent_kwargs: dict[str, Any] | None = None,
    tolerance: float | dict[str, float] = DEFAULT_TOLERANCE,
    metrics: list[str] | None = None,
    strict_actions: bool = False,
    update: bool = False,
) -> EpisodeRecord:
    """Replay an episode and compare it with its golden file (or re-record with ``update``).

    Raises GoldenMismatch when the golden file is missing or the episode moved.
    """
    path = Path(golden)
    actual = record_episode(env_id, agent, sequence, env_kwargs=env_kwargs,
                            agent_kwargs=agent_kwargs)
    if update:
        atomic_write_text(path, actual.to_json())
        return actual
    if not path.is_file():
        raise GoldenMismatch(
            f"golden file {path} does not exist; run pytest with --update-goldens to record it"
        )
    expected = EpisodeRecord.load(path)
    if (expected.env_id, expected.sequence, expected.agent) != (env_id, sequence, agent):
        raise GoldenMismatch(
            f"{path} records {expected.agent} on {expected.env_id}/{expected.sequence}, not "
            f"{agent} on {env_id}/{sequence}"
        )
    problems = compare_records(expected, actual, tolerance=tolerance, metrics=metrics,
                               strict_actions=strict_actions)
    if problems:  # options that changed since the recording come first: the likely cause
        problems = [*option_changes(expected.agent_kwargs, actual.agent_kwargs, "agent option"),
                    *option_changes(expected.env_kwargs, actual.env_kwargs, "env option"),
                    *problems]
        raise GoldenMismatch(
            f"{agent} on {env_id} / {sequence} differs from {path}:\n" + "\n".join(problems)
            + "\n(if the change is intended, re-record with pytest --update-goldens)"
        )
    return actual
