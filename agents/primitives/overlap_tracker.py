"""An appearance-free track life cycle: Hungarian matching on an overlap measure.

More in docs/module-notes.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Generic

import numpy as np
from scipy.optimize import linear_sum_assignment

from .overlap import OverlapMeasure, S


@dataclass(eq=False)
class OverlapTrack(Generic[S]):
    """One track of an :class:`OverlapTracker` (a record; the engine mutates it).

    ``state`` is the last matched detection's (a box, a mask RLE, a pose); ``hits`` counts
    matched frames, ``lost`` frames since the last match; ``velocity`` is the box motion state.
    """

    track_id: int
    state: S
    hits: int = 1
    lost: int = 0
    velocity: np.ndarray | None = None


@dataclass(frozen=True)
class OverlapReport(Generic[S]):
    """A reported track of one frame: its id, its detection's index and state."""

    track_id: int
    detection_index: int
    state: S


class OverlapTracker(Generic[S]):
    """Overlap matching with a hit-count / lost-age life cycle; :meth:`reset` clears all state.

    A match needs overlap ``threshold``; an unmatched detection overlapping a matched one by
    ``duplicate_threshold`` is a duplicate (1 = off); tracks are reported after ``min_hits``
    matches and kept ``max_lost_seconds`` unmatched.

    Example:
        >>> from unitrack_env.agents.primitives.overlap import BoxOverlap
        >>> tracker = OverlapTracker(BoxOverlap(), threshold=0.3)
        >>> box = BoxOverlap().states([[0.0, 0.0, 10.0, 20.0]])
        >>> [(r.track_id, r.detection_index) for r in tracker.step(box)]
        [(1, 0)]
    """

    def __init__(self, measure: OverlapMeasure[S], *, threshold: float,
                 duplicate_threshold: float = 1.0, min_hits: int = 2,
                 max_lost_seconds: float = 1.0, frame_rate: float = 30.0) -> None:
        self.measure = measure
        self.threshold = threshold
        self.duplicate_threshold = duplicate_threshold
        self.min_hits = min_hits
        self.max_lost_seconds = max_lost_seconds
        self.max_lost_frames = 1
        self._tracks: list[OverlapTrack[S]] = []
        self._frame = 0
        self._next_id = 1
        self.reset(frame_rate)

    def reset(self, frame_rate: float) -> None:
        """Forget every track and restart ids at 1; set the frame rate."""
        self.max_lost_frames = max(1, round(self.max_lost_seconds * frame_rate))
        self._tracks = []
        self._frame = 0
        self._next_id = 1

    @property
    def tracks(self) -> list[OverlapTrack[S]]:
        """Live tracks, oldest first (a new list)."""
        return list(self._tracks)

    def step(self, states: Sequence[S]) -> list[OverlapReport[S]]:
        """Track one frame's detection states; return the reported tracks, oldest first."""
        self._frame += 1
        det_track = self._match(states)
        matched = {id(t) for t in det_track if t is not None}
        for track in self._tracks:
            if id(track) not in matched:
                track.lost += 1
        new = [j for j, t in enumerate(det_track) if t is None]
        new = self._drop_duplicates(states, new,
                                    [j for j, t in enumerate(det_track) if t is not None])
        self._tracks = [t for t in self._tracks if t.lost <= self.max_lost_frames]
        for j in new:
            det_track[j] = self._start(states[j])
        detection_of = {id(t): j for j, t in enumerate(det_track) if t is not None}
        return [
            OverlapReport(t.track_id, detection_of[id(t)], t.state) for t in self._tracks
            if id(t) in detection_of and (self._frame <= self.min_hits or t.hits >= self.min_hits)
        ]

    def _match(self, states: Sequence[S]) -> list[OverlapTrack[S] | None]:
        """Hungarian matching; the track each detection matched (None: unmatched)."""
        det_track: list[OverlapTrack[S] | None] = [None] * len(states)
        if not self._tracks or not len(states):
            return det_track
        predicted = [self.measure.predict(t) for t in self._tracks]
        overlap = self.measure.similarity(predicted, states)
        rows, cols = linear_sum_assignment(-overlap)
        ok = overlap[rows, cols] >= self.threshold
        for row, col in zip(rows[ok].tolist(), cols[ok].tolist(), strict=True):
            track = self._tracks[row]
            self.measure.update(track, states[col])
            track.hits += 1
            track.lost = 0
            det_track[col] = track
        return det_track

    def _drop_duplicates(self, states: Sequence[S], new: list[int],
                         matched: list[int]) -> list[int]:
        if not new or not matched or self.duplicate_threshold >= 1.0:
            return new
        overlap = self.measure.similarity([states[j] for j in new],
                                          [states[j] for j in matched]).max(axis=1)
        return [j for j, o in zip(new, overlap, strict=True) if o < self.duplicate_threshold]

    def _start(self, state: S) -> OverlapTrack[S]:
        track = OverlapTrack(self._next_id, state)
        self._next_id += 1
        self._tracks.append(track)
        return track
