"""Track records of the association engine: life-cycle state, track, output, step record."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Generic, TypeVar

import numpy as np

from .kalman import xyah_to_xywh

P = TypeVar("P")
"""Type of the per-observation payload (opaque to the engine)."""


class TrackState(enum.Enum):
    """Life-cycle state of a track."""

    TENTATIVE = "tentative"
    """Born on the previous frame from an unmatched detection; not reported yet."""
    CONFIRMED = "confirmed"
    """Matched on its latest frame (after confirmation); reported."""
    LOST = "lost"
    """Confirmed earlier but unmatched on the latest frame; may still be re-found."""
    REMOVED = "removed"
    """Finished; never matched again."""



@dataclass(eq=False)
class Track(Generic[P]):
    """One track of an :class:`Associator` (a record; the engine mutates it).

    ``track_id`` is set when the track is confirmed (None while tentative); ``mean`` and
    ``covariance`` are its Kalman state; ``payload`` is the last matched observation's (or
    their moving average); frame counters are 1-based; ``key`` is an engine serial number
    that follows tentative tracks too.
    """

    track_id: int | None
    state: TrackState
    mean: np.ndarray
    covariance: np.ndarray
    payload: P
    score: float
    detection_box: np.ndarray
    start_frame: int
    last_frame: int
    hits: int = 1
    key: int = 0

    @property
    def box(self) -> np.ndarray:
        """Kalman box ``(x, y, w, h)`` (filtered after a match, predicted when lost)."""
        return xyah_to_xywh(self.mean[None, :4])[0]


@dataclass(frozen=True)
class TrackOutput:
    """A reported track of one frame: id, ``(x, y, w, h)`` box, score, and its detection's index."""

    track_id: int
    box: np.ndarray
    score: float
    detection_index: int


@dataclass
class StepRecord:
    """What one :meth:`Associator.step` did (for diagnostics; no effect on tracking).

    ``matches``: ``(track key, detection index, stage, was_lost)`` with stage ``"appearance"``,
    ``"iou"`` or ``"tentative"``; ``births``: ``(track key, detection index)``;
    ``similarities``: track key -> stage-1 similarity to every detection.
    """

    matches: list[tuple[int, int, str, bool]] = field(default_factory=list)
    births: list[tuple[int, int]] = field(default_factory=list)
    similarities: dict[int, np.ndarray] = field(default_factory=dict)

