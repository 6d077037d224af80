"""Appearance-free tracking: overlap measures and the track life cycle they drive.

A measure tells an :class:`OverlapTracker` a detection's state, how similar two sets of
states are, and how a track follows its matches: :class:`BoxOverlap` (IoU with a
constant-velocity guess), :class:`MaskOverlap` (RLE mask IoU, no motion) and
:class:`PoseOverlap` (OKS).

:class:`OverlapTracker` is the engine of the ``iou`` baseline (SORT-style, without a Kalman
filter). Per frame: match the tracks' predicted states to the detections with the Hungarian
algorithm on the measure, keeping pairs with overlap >= ``threshold``; unmatched tracks
count one more lost frame; an unmatched detection that overlaps a matched one by at least
``duplicate_threshold`` is a duplicate and starts no track, every other one starts a track;
tracks lost more than ``round(max_lost_seconds * frame_rate)`` frames (at least 1) are
dropped; tracks matched or born this frame are reported once they have ``min_hits``
matches (during an episode's first ``min_hits`` frames every one of them is).

It differs on purpose from :class:`~unitrack_env.agents.primitives.association.Associator`
with ``similarity=None`` (which keeps a Kalman filter, tentative tracks confirmed on the next
frame, and removes duplicates among tracks rather than detections): this is the baseline's
own, simpler life cycle, shared by its three observation formats.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np
from scipy.optimize import linear_sum_assignment

from unitrack_env.datasets.rle import mask_api as mask_utils
from unitrack_env.geometry import box_iou

S = TypeVar("S")
"""Type of a detection's (and a track's) state under one measure."""

OKS_SIGMAS: np.ndarray = np.array([
    0.026, 0.025, 0.025, 0.035, 0.035, 0.079, 0.079, 0.072, 0.072, 0.062, 0.062,
    0.107, 0.107, 0.087, 0.087, 0.089, 0.089,
])
"""Per-keypoint OKS falloff ``sigma`` of the 17 PoseTrack keypoints: COCO's values by position
(COCO keypoint evaluation). PoseTrack's second and third keypoints (head bottom, head top)
sit where COCO has the eyes and take their 0.025."""


def object_keypoint_similarity(
    poses_a: np.ndarray, poses_b: np.ndarray, sigmas: np.ndarray = OKS_SIGMAS
) -> np.ndarray:
    """OKS ``(n, m)`` between every pose of ``poses_a`` and every pose of ``poses_b``.

    COCO's keypoint similarity over keypoints visible (score > 0) in both, with ``s^2`` the
    area of ``a``'s visible-keypoint box (poses have no segment area); 0 when none is shared.

    >>> a = np.zeros((1, 17, 3)); a[0, :, 2] = 1; a[0, :, 0] = np.arange(17) * 10
    >>> a[0, :, 1] = np.arange(17) * 20
    >>> float(object_keypoint_similarity(a, a)[0, 0])
    1.0
    """
    a = np.asarray(poses_a, dtype=np.float64)
    b = np.asarray(poses_b, dtype=np.float64)
    if not len(a) or not len(b):
        return np.zeros((len(a), len(b)))
    vis_a = a[:, :, 2] > 0
    vis_b = b[:, :, 2] > 0
    area = np.zeros(len(a))
    for i in range(len(a)):
        pts = a[i, vis_a[i], :2]
        if len(pts):
            w, h = pts.max(axis=0) - pts.min(axis=0)
            area[i] = w * h
    area = np.maximum(area, 1.0)  # a single visible keypoint: a 1-pixel object
    d2 = ((a[:, None, :, :2] - b[None, :, :, :2]) ** 2).sum(-1)  # (n, m, K)
    kappa2 = (2.0 * np.asarray(sigmas, dtype=np.float64)) ** 2
    sim = np.exp(-d2 / (2.0 * area[:, None, None] * kappa2[None, None, :]))
    both = vis_a[:, None, :] & vis_b[None, :, :]
    count = both.sum(-1)
    return np.where(count > 0, (sim * both).sum(-1) / np.maximum(count, 1), 0.0)


class OverlapMeasure(abc.ABC, Generic[S]):
    """How an overlap tracker compares detections with tracks (no appearance)."""

    @abc.abstractmethod
    def states(self, detections: Any) -> list[S]:
        """One state per detection of a frame (e.g. the rows of a box array)."""

    @abc.abstractmethod
    def similarity(self, a: Sequence[S], b: Sequence[S]) -> np.ndarray:
        """``(len(a), len(b))`` overlap of two non-empty state lists."""

    def predict(self, track: OverlapTrack[S]) -> S:
        """Where ``track`` is expected now (default: its last state)."""
        return track.state

    def update(self, track: OverlapTrack[S], state: S) -> None:
        """Follow a match (called before the track's hit and lost counts change)."""
        track.state = state


class BoxOverlap(OverlapMeasure[np.ndarray]):
    """Box IoU with a constant-velocity guess (``velocity_smoothing``: newest step weight)."""

    def __init__(self, velocity_smoothing: float = 0.5) -> None:
        self.velocity_smoothing = velocity_smoothing

    def states(self, detections: Any) -> list[np.ndarray]:
        """The rows of an ``(m, 4)`` ``(x, y, w, h)`` box array, as float64."""
        return list(np.asarray(detections, dtype=np.float64).reshape(-1, 4))

    def similarity(self, a: Sequence[np.ndarray], b: Sequence[np.ndarray]) -> np.ndarray:
        """Box IoU."""
        return box_iou(np.stack(a), np.stack(b))

    def predict(self, track: OverlapTrack[np.ndarray]) -> np.ndarray:
        """Last box plus the velocity times the frames since the last match (and this one)."""
        return track.state + self._velocity(track) * (track.lost + 1)

    def update(self, track: OverlapTrack[np.ndarray], state: np.ndarray) -> None:
        """Smooth the velocity with the displacement per frame, then take the new box."""
        displacement = (state - track.state) / (track.lost + 1)
        a = self.velocity_smoothing
        track.velocity = displacement if track.hits == 1 \
            else a * displacement + (1 - a) * self._velocity(track)
        track.state = state

    @staticmethod
    def _velocity(track: OverlapTrack[np.ndarray]) -> np.ndarray:
        return track.velocity if track.velocity is not None else np.zeros(4)


class MaskOverlap(OverlapMeasure[dict]):
    """Mask IoU on ``pycocotools`` run-length encodings (no motion)."""

    def states(self, detections: Any) -> list[dict]:
        """The RLE of each mask of an ``(m, H, W)`` bool stack."""
        masks = np.asarray(detections, dtype=bool)
        if not len(masks):
            return []
        return list(mask_utils.encode(np.asfortranarray(masks.transpose(1, 2, 0).astype(np.uint8))))

    def similarity(self, a: Sequence[dict], b: Sequence[dict]) -> np.ndarray:
        """Mask IoU (no crowd regions)."""
        return np.asarray(mask_utils.iou(list(a), list(b), [False] * len(b))
                          ).reshape(len(a), len(b))


class PoseOverlap(OverlapMeasure[np.ndarray]):
    """Object keypoint similarity (:func:`object_keypoint_similarity`; no motion)."""

    def __init__(self, sigmas: np.ndarray = OKS_SIGMAS) -> None:
        self.sigmas = sigmas

    def states(self, detections: Any) -> list[np.ndarray]:
        """The poses of an ``(m, K, 3)`` array."""
        return list(np.asarray(detections))

    def similarity(self, a: Sequence[np.ndarray], b: Sequence[np.ndarray]) -> np.ndarray:
        """OKS of ``a``'s poses (their areas) against ``b``'s."""
        return object_keypoint_similarity(np.stack(a), np.stack(b), self.sigmas)


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
