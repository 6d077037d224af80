"""Detection score scales as data: the range each benchmark's detection scores are on.

FRCNN and SDP confidences are in 0..1; MOT15's ACF scores are unbounded (PETS09-S2L1:
-0.48 to 138.92). A threshold means nothing without the scale, so each benchmark declares
a :class:`ScoreRange`, reported as ``info["detection_scores"]``; agents state thresholds on
0..1 and map them with :meth:`ScoreRange.from_unit`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

#: Values of the environments' ``detection_scores`` option.
SCORE_MODES: tuple[str, ...] = ("raw", "unit")


@dataclass(frozen=True)
class ScoreRange:
    """The scale of a benchmark's detection scores: ``low`` maps to 0, ``high`` to 1.

    ``bounded`` False means scores can fall outside (the unit scale clips them); ``source``
    says where the range comes from.
    """

    low: float
    high: float
    bounded: bool
    source: str

    def __post_init__(self) -> None:
        if not (np.isfinite(self.low) and np.isfinite(self.high) and self.high > self.low):
            raise ValueError(f"a score range needs finite low < high, got "
                             f"({self.low!r}, {self.high!r})")

    @property
    def is_unit(self) -> bool:
        """Whether the range is already 0..1."""
        return self.low == 0.0 and self.high == 1.0

    def to_unit(self, scores: np.ndarray) -> np.ndarray:
        """``scores`` mapped linearly to 0..1 (``low`` -> 0, ``high`` -> 1) and clipped."""
        scores = np.asarray(scores, dtype=np.float64)
        if not self.is_unit:
            scores = (scores - self.low) / (self.high - self.low)
        return np.clip(scores, 0.0, 1.0)

    def from_unit(self, value: float) -> float:
        """A threshold stated on 0..1, on this range (``low + value * (high - low)``)."""
        return float(self.low + value * (self.high - self.low))

    def info(self) -> dict[str, Any]:
        """The range as ``info["detection_scores"]`` carries it."""
        return {"low": self.low, "high": self.high, "bounded": self.bounded,
                "source": self.source}

    @classmethod
    def from_info(cls, info: Mapping[str, Any] | None) -> ScoreRange | None:
        """The range an environment declared in ``info["detection_scores"]`` (None: none)."""
        if not info:
            return None
        return cls(float(info["low"]), float(info["high"]), bool(info.get("bounded", True)),
                   str(info.get("source", "")))

    @classmethod
    def of(cls, value: ScoreRange | tuple[float, float] | list[float]) -> ScoreRange:
        """A range given as a :class:`ScoreRange` or ``(low, high)`` (a user's own data)."""
        if isinstance(value, ScoreRange):
            return value
        low, high = (float(v) for v in value)
        return cls(low, high, False, "given by the user (score_range=)")


UNIT = ScoreRange(0.0, 1.0, True, "scores in 0..1")
"""The unit range: what ``detection_scores="unit"`` hands out."""

_CONFIDENCE = "a detector confidence in 0..1"

DETECTION_SCORES: Mapping[str, ScoreRange] = MappingProxyType({
    "MOT15": ScoreRange(
        0.0, 100.0, False,
        "MOT15's ACF detections are unbounded detector scores; PETS09-S2L1's det.txt "
        "(frames 1-400, 2905 rows) runs from -0.48 to 138.92; 0..100 is their nominal scale"),
    "MOT16": ScoreRange(
        0.0, 1.0, True,
        "declared 0..1 like MOT17 (the synthetic MOT16 default: 0.01..0.999); MOT16's public "
        "DPM files were not measured here: pass score_range= if yours differ"),
    "MOT17": ScoreRange(
        0.0, 1.0, True,
        "FRCNN/SDP confidences; MOT17-02/04/05/11-FRCNN (first 4-8 frames, 332 rows) run "
        "from 0.051 to 1; the *-DPM files were not measured here: pass score_range= for them"),
    "MOT20": ScoreRange(0.0, 1.0, True, f"MOT20's public detections: {_CONFIDENCE}"),
    "DanceTrack": ScoreRange(0.0, 1.0, True, "DanceTrack ships no detections; yours are taken "
                             f"as {_CONFIDENCE}: pass score_range= if they are not"),
    "SportsMOT": ScoreRange(0.0, 1.0, True, "SportsMOT ships no detections; yours are taken "
                            f"as {_CONFIDENCE}: pass score_range= if they are not"),
    "MOTS20": ScoreRange(0.0, 1.0, True, f"MOTS detections: {_CONFIDENCE}"),
    "YouTube-VIS-2019": ScoreRange(0.0, 1.0, True, f"VIS result files: {_CONFIDENCE}"),
    "PoseTrack2018": ScoreRange(0.0, 1.0, True, f"PoseTrack detected poses: {_CONFIDENCE}"),
})
"""Benchmark name -> the range of its public detection scores (read-only)."""


def declared_range(benchmark: str) -> ScoreRange:
    """The declared range of ``benchmark``'s detection scores (0..1 when not declared)."""
    return DETECTION_SCORES.get(benchmark, UNIT)


def check_mode(mode: str) -> str:
    """``mode`` if it is a valid ``detection_scores`` option, else a ValueError."""
    if mode not in SCORE_MODES:
        raise ValueError(f"detection_scores must be one of {', '.join(SCORE_MODES)}, "
                         f"got {mode!r}")
    return mode
