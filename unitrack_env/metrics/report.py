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

    Metrics are fractions. ``scores`` holds the task's full results (not serialised);
    ``sequences_of`` is the split's sequence count (0: not known); ``missing`` lists
    sequences without a result file (``allow_missing=True``).
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
