"""Keeping finished sequences across an edit of the agent's code that cannot change them.

A finished sequence is played again when the agent's code changed (:mod:`.agent_code`). When
you know an edit cannot move a result (a comment, a log line, a rename), ``--restamp`` on
``unitrack evaluate`` and ``unitrack scorecard`` (``restamp=True`` in :func:`~.runner.run`)
keeps such sequences instead: a record is re-stamped only after it is shown that the code is
all that changed, that is, that the record's fingerprint is rebuilt exactly from its stored
code manifest with today's data, options and environment; its result files must still hold
their recorded digest. The changed files are reported for every sequence kept, so the claim
is yours and visible.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from unitrack_env.io import atomic_write_text

from .agent_code import code_changes
from .episode import SequenceRecord
from .identity import RunIdentity, Stamp, result_digest


def restamp_record(out: Path, spec: Any, base: Any, sequence: str, inputs: Iterable[Path],
                   now: Stamp) -> list[str] | str:
    """Re-stamp one stored record whose only change is the agent's code.

    Args:
        out: The run folder.
        spec: The run's :class:`~.run_spec.RunSpec` (today's options and environment).
        base: The unwrapped environment (its sequences and data folder).
        sequence: The sequence.
        inputs: The sequence's input files, as the runner fingerprints them.
        now: The stamp a record made today would carry.

    Returns:
        The changed code files (the record now carries ``now``), or why it cannot be kept.
    """
    path = out / "sequences" / f"{sequence}.json"
    try:
        record = SequenceRecord.from_json(json.loads(path.read_text()))
    except (OSError, ValueError, TypeError):
        return "its record is unreadable"
    if record.results != result_digest(out / "data", sequence, base.sequence_names):
        return "its result files are missing or were changed since it was played"
    if record.inputs == now.inputs:
        return []  # nothing to re-stamp
    if not isinstance(record.code, dict):
        return "its record holds no code manifest, so a code-only change cannot be shown"
    then = RunIdentity.of(spec, code=record.code).sequence_fingerprint(inputs,
                                                                       base.inputs_root())
    if then != record.inputs:
        return "its data files or options changed too"
    changed = code_changes(record.code, now.code)
    now.apply(record)
    atomic_write_text(path, json.dumps(record.to_json(), indent=2))
    return changed
