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
        sequences_of: how many sequences the split has to score (0: not known).
        missing: sequences asked for that had no result file (``allow_missing=True``).
    """

    benchmark: str
    per_sequence: dict[str, dict[str, float]]
    combined: dict[str, float]
    scores: dict[str, Any] = field(default_factory=dict, repr=False)
    sequences_of: int = 0
    missing: list[str] = field(default_factory=list)

    @property
    def coverage(self) -> str:
        """What the combined row covers: ``"7 of 7 sequences"`` (``"7 sequences"``)."""
        scored = len(self.per_sequence)
        if self.sequences_of:
            return f"{scored} of {self.sequences_of} sequences"
        return f"{scored} sequence{'s' if scored != 1 else ''}"

    def coverage_json(self) -> dict[str, Any]:
        """``{"scored": 7, "of": 7, "missing": []}`` (``of`` null when not known)."""
        return {"scored": len(self.per_sequence), "of": self.sequences_of or None,
                "missing": list(self.missing)}

    def to_json(self, *, indent: int | None = 2) -> str:
        """Serialise benchmark, per-sequence and combined metrics as JSON text."""
        payload = {
            "benchmark": self.benchmark,
            "per_sequence": self.per_sequence,
            "combined": self.combined,
            "sequences": self.coverage_json(),
        }
        return json.dumps(payload, indent=indent, sort_keys=False)
