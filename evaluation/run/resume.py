"""What a run folder already holds: whether it is this run, which finished sequences it keeps.

A finished sequence is kept when its record's stamp (:class:`~.identity.Stamp`) matches
today's data, options and agent code and its result files are intact; otherwise it is played
again, and the reason says what changed. :func:`stale_sequences` and
:func:`restamp_sequences` answer without playing (the scorecard sends stale cells to its
workers, and keeps code-only edits with ``--restamp``).
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from unitrack_env.agents.base import agent_class
from unitrack_env.agents.loading import portable_reference
from unitrack_env.benchmarks.base import select_sequences

from .agent_code import code_changes
from .episode import SequenceRecord
from .identity import (
    RunIdentity,
    Stamp,
    option_changes,
    placeless_options,
    placeless_reference,
    result_digest,
)
from .ownership import outside
from .restamp import restamp_record
from .run_spec import RunSpec


class RunMismatch(ValueError):
    """The output folder holds another run (``difference`` says what differs)."""

    def __init__(self, out: Path, difference: str) -> None:
        self.out, self.difference = out, difference
        super().__init__(f"{out} already holds a different run ({difference}); choose another "
                         "--out, or replace it with --overwrite (overwrite=True in run())")

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.out, self.difference))


#: run.json fields as a difference names them.
_RUN_FIELDS = {"env_id": "env", "agent": "agent", "agent_ref": "agent class",
               "env_kwargs": "env option", "agent_kwargs": "agent option"}


def _run_difference(previous: Any, spec: RunSpec) -> str:
    """What differs between a stored ``run.json`` and ``spec``, in a user's words."""
    if not isinstance(previous, dict):
        return "its run.json is unreadable"
    now = spec.to_json()
    changes = []
    for key, label in _RUN_FIELDS.items():
        old, new = previous.get(key), now.get(key)
        if isinstance(old, dict) and isinstance(new, dict):
            changes += option_changes(old, new, label)
        elif old != new:
            changes.append(f"{label}: {old!r} -> {new!r}")
    if previous.get("repeats", 1) != now.get("repeats", 1):
        changes.append(f"--repeats: {previous.get('repeats', 1)!r} -> {now.get('repeats', 1)!r}")
    return "; ".join(changes) or "another run.json format"


def _same_run(previous: Any, now: dict[str, Any]) -> bool:
    """Whether a stored ``run.json`` describes this run; its files may have moved.

    Another ``root`` holding the same data resumes: the sequences' input fingerprints name
    files relative to it, and a sequence whose files differ is played again. So do a
    checkpoint (any option naming a file) and an agent file given from another folder: the
    identity counts them by base name and content.
    """
    if not isinstance(previous, dict) or not all(
            isinstance(previous.get(key), dict) for key in ("env_kwargs", "agent_kwargs")):
        return previous == now

    def placeless_run(run: dict[str, Any]) -> dict[str, Any]:
        env = {k: v for k, v in run["env_kwargs"].items() if k != "root"}
        return run | {"env_kwargs": placeless_options(env, now["env_kwargs"]),
                      "agent_kwargs": placeless_options(run["agent_kwargs"], now["agent_kwargs"]),
                      "agent": placeless_reference(run.get("agent")),
                      "agent_ref": placeless_reference(run.get("agent_ref")),
                      "rooted": "root" in run["env_kwargs"]}

    return placeless_run(previous) == placeless_run(now)


def check_run_json(out: Path, spec: RunSpec) -> None:
    """Refuse a folder whose ``run.json`` describes another run.

    Raises:
        RunMismatch: naming what differs.
    """
    run_file = out / "run.json"
    if not run_file.is_file():
        return
    try:
        previous = json.loads(run_file.read_text())
    except ValueError:
        previous = None
    if not _same_run(previous, spec.to_json()):
        raise RunMismatch(out, _run_difference(previous, spec))


def record_path(out: Path, sequence: str) -> Path:
    """Where a finished sequence's record is (it marks the sequence done)."""
    return out / "sequences" / f"{sequence}.json"


def stale_reason(out: Path, base: Any, name: str, stamp: Stamp) -> str | None:
    """Why a finished sequence must be played again (None: keep it)."""
    try:
        record = SequenceRecord.from_json(json.loads(record_path(out, name).read_text()))
    except (OSError, ValueError, TypeError):
        return "its record is unreadable"
    if record.inputs != stamp.inputs:
        if isinstance(record.code, dict) and (changed := code_changes(record.code, stamp.code)):
            shown = ", ".join(changed[:3]) + (f" and {len(changed) - 3} more"
                                               if len(changed) > 3 else "")
            return f"the agent's code changed since it was played ({shown})"
        return "its inputs (data files, agent code or options) changed since it was played"
    if record.results != result_digest(out / "data", name, base.sequence_names):
        return "its result files are missing or were changed since it was played"
    return None


def _stored_repeats(out: Path) -> int:
    """The ``repeats`` of the run stored in ``out`` (1 when it has none or no readable run.json)."""
    try:
        repeats = json.loads((out / "run.json").read_text()).get("repeats", 1)
    except (OSError, ValueError, AttributeError):
        return 1
    return repeats if isinstance(repeats, int) and not isinstance(repeats, bool) and \
        repeats >= 1 else 1


@contextlib.contextmanager
def _stored_run(env_id: str, agent: str | type, out: Path, env_kwargs: dict[str, Any] | None,
                agent_kwargs: dict[str, Any] | None, sequences: Sequence[str] | None,
                ) -> Iterator[tuple[RunSpec, Any, dict[str, tuple[list[Path], Stamp]]]]:
    """A run folder's spec, environment and finished sequences (input files, today's stamp).

    Raises:
        RunMismatch: ``out`` holds another run.
    """
    agent_kwargs = dict(agent_kwargs or {})
    cls = agent_class(agent)
    name = agent if isinstance(agent, str) else (getattr(cls, "name", "") or cls.__qualname__)
    spec = RunSpec(env_id, name, portable_reference(cls), dict(env_kwargs or {}), agent_kwargs,
                   _stored_repeats(out))
    check_run_json(out, spec)
    env = spec.make_env()
    try:
        base = env.unwrapped
        names = select_sequences(sequences, base.sequence_names, env_id)
        identity = RunIdentity.of(spec)
        finished = {}
        for n in names:
            if record_path(out, n).is_file():
                inputs = outside(base.sequence_inputs(n), out)
                finished[n] = (inputs, identity.stamp(inputs, base.inputs_root()))
        yield spec, base, finished
    finally:
        env.close()


def stale_sequences(env_id: str, agent: str | type, out: str | os.PathLike[str], *,
                    env_kwargs: dict[str, Any] | None = None,
                    agent_kwargs: dict[str, Any] | None = None,
                    sequences: Sequence[str] | None = None) -> dict[str, str]:
    """The finished sequences in ``out`` that a rerun would play again, with the reason.

    Nothing is played and the agent is not built: its class is imported (its code counts in
    the fingerprints) and the environment reads its files. Sequences without a record are
    not listed (they are unplayed, not stale).

    Raises:
        RunMismatch: ``out`` holds another run (as :func:`~.runner.run` would refuse it; its
            sequences are not stale, they are someone else's).
    """
    out = Path(out)
    with _stored_run(env_id, agent, out, env_kwargs, agent_kwargs, sequences) as (_, base, done):
        return {n: why for n, (_, stamp) in done.items()
                if (why := stale_reason(out, base, n, stamp)) is not None}


def restamp_sequences(env_id: str, agent: str | type, out: str | os.PathLike[str], *,
                      env_kwargs: dict[str, Any] | None = None,
                      agent_kwargs: dict[str, Any] | None = None,
                      sequences: Sequence[str] | None = None) -> dict[str, list[str] | str]:
    """Re-stamp the finished sequences in ``out`` whose only change is the agent's code.

    Returns, for each sequence a rerun would play again, the changed code files (it is kept)
    or why it cannot be kept (:func:`.restamp.restamp_record`). Nothing is played.

    Raises:
        RunMismatch: ``out`` holds another run.
    """
    out = Path(out)
    with _stored_run(env_id, agent, out, env_kwargs, agent_kwargs, sequences) as (
            spec, base, done):
        return {n: restamp_record(out, spec, base, n, inputs, stamp)
                for n, (inputs, stamp) in done.items()
                if stale_reason(out, base, n, stamp) is not None}
