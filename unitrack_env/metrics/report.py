"""Scores of a folder of results: per sequence and combined, for every task."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

#: Key of the combined row, as TrackEval's tables label it.
COMBINED: str = "COMBINED"

@dataclass
class ScoreReport:
    """Per-sequence and combined TrackEval metrics of one results folder.

    Attributes:
        benchmark: the benchmark (rule set) scored.
        per_sequence: ``{sequence: {field: value}}`` (fractions, not percent).
        combined: metrics over all sequences (TrackEval's ``COMBINED_SEQ``).
        scores: task-specific full results per sequence (for MOT, TrackEval's
            :class:`~unitrack_env.metrics.motchallenge.SequenceScore`), including
            ``COMBINED``; not serialised by :meth:`to_json`.
    """

    benchmark: str
    per_sequence: dict[str, dict[str, float]]
    combined: dict[str, float]
    scores: dict[str, Any] = field(default_factory=dict, repr=False)

    def to_json(self, *, indent: int | None = 2) -> str:
        """Serialise benchmark, per-sequence and combined metrics as JSON text."""
        payload = {
            "benchmark": self.benchmark,
            "per_sequence": self.per_sequence,
            "combined": self.combined,
        }
        return json.dumps(payload, indent=indent, sort_keys=False)
