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

    Attributes:
        track_id: Public id (>= 1), assigned when the track is confirmed; ``None`` while
            tentative.
        state: Life-cycle state.
        mean: ``(8,)`` Kalman state ``(u, v, a, h, du, dv, da, dh)``.
        covariance: ``(8, 8)`` Kalman covariance.
        payload: Payload of the last matched observation (or the moving average of the
            matched ones, see ``AssociationConfig.appearance_momentum``).
        score: Score of the last matched detection.
        detection_box: ``(4,)`` ``(x, y, w, h)`` of the last matched detection.
        start_frame: Episode frame counter (1-based) at birth.
        last_frame: Episode frame counter of the last match.
        hits: Number of matched frames.
        key: Engine-internal serial number (unique per episode, tentative tracks included);
            diagnostics use it to follow a track before it has a public id.
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
    """A reported track of one frame.

    Attributes:
        track_id: Public id (>= 1).
        box: ``(4,)`` ``float64`` ``(x, y, w, h)``.
        score: Score of the matched detection.
        detection_index: Index of the matched detection in this frame's input.
    """

    track_id: int
    box: np.ndarray
    score: float
    detection_index: int


@dataclass
class StepRecord:
    """What one :meth:`Associator.step` did (for diagnostics; no effect on tracking).

    Attributes:
        matches: ``(track key, detection index, stage, was_lost)`` per match, where stage is
            ``"appearance"`` (stage 1), ``"iou"`` (stage 2) or ``"tentative"``
            (confirmation), and ``was_lost`` says the track was lost before this frame.
        births: ``(track key, detection index)`` of the tracks started in this frame.
        similarities: Track key -> ``(m,)`` stage-1 similarity of that track to every
            detection of the frame (tracks offered to stage 1 only).
    """

    matches: list[tuple[int, int, str, bool]] = field(default_factory=list)
    births: list[tuple[int, int]] = field(default_factory=list)
    similarities: dict[int, np.ndarray] = field(default_factory=dict)

