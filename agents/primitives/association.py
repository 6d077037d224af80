"""Track life cycle and the paper's two-stage association, as a task-agnostic engine.

:class:`Associator` implements Algorithm 1 of the UniTrack paper (appendix C.1, JDE's
association). Per detection it gets a box (Kalman filter, IoU stages) and an opaque
*payload* compared by an injected ``similarity(tracks, detections) -> (n, m)``; the
appearance cost is ``1 - similarity`` (for RSM the paper's ``1 - (cos_fwd + cos_bwd) / 2``).
One :meth:`Associator.step` per frame:

1. Predict every live track (lost ones with their height velocity frozen).
2. Stage 1, appearance: confirmed and lost tracks against all detections, cost
   ``lambda C_a + (1 - lambda) Mahalanobis^2`` with gated pairs at ``inf``, accepted below
   ``appearance_threshold``; without motion (the paper's "w/o motion") ``C_a`` alone, ungated.
3. Stage 2, IoU: the remaining *confirmed* tracks against the remaining detections,
   accepted at ``IoU > iou_threshold`` (with and without motion, as the authors' code).
4. Tentative tracks (born last frame): confirmed at ``IoU > confirm_iou_threshold``, else
   removed.
5. Unmatched confirmed tracks become lost; lost ones older than
   ``round(lost_seconds * frame_rate)`` frames are removed.
6. Each remaining detection with ``score >= new_track_raw_score`` starts a tentative track
   (confirmed at once on an episode's first frame, as in the code).
7. An active and a lost track with ``IoU > duplicate_iou`` are one object: the younger goes.

The output is the confirmed tracks matched this frame (optionally the MOT output filter).
Tracks keep their last payload unless ``appearance_momentum`` asks for an average
(:mod:`~unitrack_env.agents.primitives.appearance_memory`). Where the engine departs from
the letter of Algorithm 1 it follows the authors' code: gated pairs are excluded *before*
the Hungarian step (so an impossible pair cannot block a valid one) and lost tracks skip the
IoU stage. One deliberate difference from the code: ids are assigned at confirmation, so
reported ids are consecutive.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Generic

import numpy as np

from unitrack_env.geometry import box_iou

from .appearance_memory import remember
from .association_config import AssociationConfig
from .kalman import KalmanFilter, xywh_to_xyah
from .matching import fuse_motion, iou_cost, linear_assignment
from .tracks import (
    P,
    StepRecord,
    Track,
    TrackOutput,
    TrackState,
)

__all__ = ["HEIGHT_VELOCITY_INDEX", "Associator", "SimilarityFn"]

SimilarityFn = Callable[[Sequence[Any], Sequence[Any]], Any]
"""``similarity(track_payloads, detection_payloads)`` -> ``(n, m)`` array-like similarity.

Higher means more similar; the appearance cost is ``1 - similarity``. Torch tensors are
accepted (converted with ``numpy.asarray`` after ``.detach().cpu()``).
"""

HEIGHT_VELOCITY_INDEX = 7
"""Index of ``dh`` (height velocity) in the Kalman state ``(u, v, a, h, du, dv, da, dh)``."""


@dataclass
class _Frame(Generic[P]):
    """One frame's detections while :meth:`Associator.step` runs."""

    boxes: np.ndarray
    measurements: np.ndarray
    scores: np.ndarray
    payloads: Sequence[P]
    frame: int
    was_lost: set[int]
    matched: dict[int, Track[P]] = field(default_factory=dict)


class Associator(Generic[P]):
    """Two-stage association with the track life cycle; :meth:`reset` clears all state.

    ``similarity=None`` skips the appearance stage and offers confirmed and lost tracks to the
    IoU stage (an IoU/SORT-style control).

    Example:
        >>> import numpy as np
        >>> same = lambda a, b: np.ones((len(a), len(b)))
        >>> assoc = Associator(same)
        >>> out = assoc.step(np.array([[0.0, 0.0, 10.0, 20.0]]), np.array([0.9]), ["x"])
        >>> [(t.track_id, t.box.tolist()) for t in out]
        [(1, [0.0, 0.0, 10.0, 20.0])]
    """

    def __init__(
        self,
        similarity: SimilarityFn | None,
        config: AssociationConfig | None = None,
        frame_rate: float = 30.0,
    ) -> None:
        self.similarity = similarity
        self.config = config if config is not None else AssociationConfig()
        self.kalman = KalmanFilter(self.config.kalman)
        self._frame_rate = 30.0
        self._tracks: list[Track[P]] = []
        self._frame = 0
        self._next_id = 1
        self._next_key = 1
        self.last_step = StepRecord()
        self.reset(frame_rate)

    # ------------------------------------------------------------------ state
    def reset(self, frame_rate: float | None = None) -> None:
        """Forget every track and restart ids at 1; ``frame_rate=None`` keeps the current one."""
        if frame_rate is not None:
            if not (np.isfinite(frame_rate) and frame_rate > 0):
                raise ValueError(f"frame_rate must be a positive number, got {frame_rate!r}")
            self._frame_rate = float(frame_rate)
        self._tracks = []
        self._frame = 0
        self._next_id = 1
        self._next_key = 1
        self.last_step = StepRecord()

    @property
    def frame_rate(self) -> float:
        """Frames per second used for the lost-track age."""
        return self._frame_rate

    @property
    def max_lost_frames(self) -> int:
        """Frames a lost track is kept: ``round(lost_seconds * frame_rate)``."""
        return int(round(self.config.lost_seconds * self._frame_rate))

    @property
    def frame_index(self) -> int:
        """Number of frames processed since the last reset."""
        return self._frame

    @property
    def tracks(self) -> list[Track[P]]:
        """Live (tentative, confirmed and lost) tracks, in birth order (a new list)."""
        return list(self._tracks)

    # ------------------------------------------------------------------ one frame
    def step(
        self, boxes: np.ndarray, scores: np.ndarray, payloads: Sequence[P]
    ) -> list[TrackOutput]:
        """Associate one frame's ``(x, y, w, h)`` boxes; return the matched confirmed tracks."""
        boxes, scores = self._check_inputs(boxes, scores, payloads)
        self._frame += 1
        self.last_step = StepRecord()
        now = _Frame(boxes, xywh_to_xyah(boxes), scores, payloads, self._frame,
                     {t.key for t in self._tracks if t.state is TrackState.LOST})
        self._predict_all()
        tentative = [t for t in self._tracks if t.state is TrackState.TENTATIVE]
        pool = [t for t in self._tracks if t.state in (TrackState.CONFIRMED, TrackState.LOST)]
        remaining = self._associate(now, pool, tentative)
        self._age(now.frame, pool, tentative)
        self._birth(now, remaining)
        self._remove_duplicates(now.frame)
        self._tracks = [t for t in self._tracks if t.state is not TrackState.REMOVED]
        return self._outputs(now.matched, now.frame)

    def _associate(
        self, now: _Frame[P], pool: list[Track[P]], tentative: list[Track[P]]
    ) -> np.ndarray:
        """Stage 1 (appearance), stage 2 (IoU) and confirmation; the detections left over."""
        cfg = self.config
        unmatched = np.ones(len(now.boxes), dtype=bool)
        if self.similarity is not None:
            for row, det in self._appearance_stage(pool, now.measurements, now.payloads):
                self._accept(pool[row], int(det), now, "appearance")
                unmatched[det] = False
        # Stage 2: IoU on Kalman-predicted boxes for the remaining tracked tracks. Without
        # an appearance stage lost tracks are offered here too (else they could never return).
        offer_lost = cfg.iou_stage_includes_lost or self.similarity is None
        candidates = [
            t for t in pool
            if t.last_frame != now.frame and (t.state is TrackState.CONFIRMED or offer_lost)
        ]
        remaining = self._iou_stage(candidates, np.flatnonzero(unmatched), cfg.iou_threshold,
                                    now, "iou")
        # Tentative tracks: confirmed by an overlapping detection (removed otherwise, in _age).
        return self._iou_stage(tentative, remaining, cfg.confirm_iou_threshold, now, "tentative")

    def _age(self, frame: int, pool: list[Track[P]], tentative: list[Track[P]]) -> None:
        """Unmatched: tentative tracks are removed, confirmed ones lost, old lost ones removed."""
        for track in tentative:
            if track.last_frame != frame:
                track.state = TrackState.REMOVED
        for track in pool:
            if track.last_frame == frame:
                continue
            track.state = TrackState.LOST
            if frame - track.last_frame > self.max_lost_frames:
                track.state = TrackState.REMOVED

    def _birth(self, now: _Frame[P], remaining: np.ndarray) -> None:
        """New tracks from the confident unmatched detections."""
        cfg = self.config
        first = now.frame == 1 and cfg.confirm_on_first_frame
        new_tracks = []
        for j in remaining:
            if now.scores[j] >= cfg.new_track_raw_score:
                track = self._new_track(int(j), now, first)
                now.matched[int(j)] = track
                new_tracks.append(track)
                self.last_step.births.append((track.key, int(j)))
        self._tracks.extend(new_tracks)

    # ------------------------------------------------------------------ internals
    def _check_inputs(
        self, boxes: np.ndarray, scores: np.ndarray, payloads: Sequence[P]
    ) -> tuple[np.ndarray, np.ndarray]:
        b = np.asarray(boxes, dtype=np.float64)
        if b.size == 0:
            b = b.reshape(0, 4)
        if b.ndim != 2 or b.shape[1] != 4:
            raise ValueError(f"boxes must have shape (m, 4) as (x, y, w, h), got {b.shape}")
        s = np.asarray(scores, dtype=np.float64).reshape(-1)
        if len(s) != len(b) or len(payloads) != len(b):
            raise ValueError(
                f"got {len(b)} boxes, {len(s)} scores and {len(payloads)} payloads; "
                "they must have the same length"
            )
        if not np.all(np.isfinite(b)):
            raise ValueError("boxes contain NaN or infinite values")
        if np.any(b[:, 2:] <= 0):
            bad = int(np.flatnonzero(np.any(b[:, 2:] <= 0, axis=1))[0])
            raise ValueError(
                f"box {bad} has a non-positive width or height ({b[bad].tolist()}); "
                "drop empty boxes before association"
            )
        return b, s

    def _predict_all(self) -> None:
        if not self._tracks:
            return
        means = np.stack([t.mean for t in self._tracks])
        covs = np.stack([t.covariance for t in self._tracks])
        if self.config.freeze_lost_height_velocity:
            lost = np.array([t.state is TrackState.LOST for t in self._tracks])
            means[lost, HEIGHT_VELOCITY_INDEX] = 0.0
        means, covs = self.kalman.predict(means, covs)
        for track, mean, cov in zip(self._tracks, means, covs, strict=True):
            track.mean, track.covariance = mean, cov

    def _appearance_stage(
        self, pool: list[Track[P]], measurements: np.ndarray, payloads: Sequence[P]
    ) -> np.ndarray:
        if not pool or len(measurements) == 0:
            return np.empty((0, 2), dtype=np.int64)
        assert self.similarity is not None
        sim = _to_numpy(self.similarity([t.payload for t in pool], payloads))
        if sim.shape != (len(pool), len(measurements)):
            raise ValueError(
                f"similarity returned shape {sim.shape}, expected "
                f"({len(pool)} tracks, {len(measurements)} detections)"
            )
        for track, row in zip(pool, sim, strict=True):
            self.last_step.similarities[track.key] = row
        cost = 1.0 - sim
        cfg = self.config
        if cfg.use_motion:
            means = np.stack([t.mean for t in pool])
            covs = np.stack([t.covariance for t in pool])
            motion = self.kalman.gating_distance(means, covs, measurements)
            cost = fuse_motion(cost, motion, cfg.appearance_weight, cfg.gate_threshold)
        if cfg.reid_threshold is not None:
            lost = np.array([t.state is TrackState.LOST for t in pool])
            cost[lost] = np.where(cost[lost] < cfg.reid_threshold, cost[lost], np.inf)
        matches = linear_assignment(cost, cfg.appearance_threshold).matches
        if cfg.ambiguity_margin > 0 and len(matches):
            matches = _unambiguous(cost, matches, cfg.appearance_threshold,
                                   cfg.ambiguity_margin)
        return matches

    def _iou_stage(
        self, tracks: list[Track[P]], dets: np.ndarray, threshold: float, now: _Frame[P],
        stage: str,
    ) -> np.ndarray:
        if not tracks or len(dets) == 0:
            return dets
        track_boxes = np.stack([t.box for t in tracks])
        cost = iou_cost(track_boxes, now.boxes[dets])
        assignment = linear_assignment(cost, 1.0 - threshold)
        for row, col in assignment.matches:
            self._accept(tracks[row], int(dets[col]), now, stage)
        return dets[assignment.unmatched_cols]

    def _accept(self, track: Track[P], det: int, now: _Frame[P], stage: str) -> None:
        """Match ``track`` with detection ``det`` in ``stage`` and record it."""
        self._match(track, det, now)
        now.matched[det] = track
        self.last_step.matches.append((track.key, det, stage, track.key in now.was_lost))

    def _match(self, track: Track[P], det: int, now: _Frame[P]) -> None:
        mean, cov = self.kalman.update(
            track.mean[None], track.covariance[None], now.measurements[det : det + 1]
        )
        track.mean, track.covariance = mean[0], cov[0]
        momentum = self.config.appearance_momentum
        track.payload = remember(track.payload, now.payloads[det], momentum)
        track.score = float(now.scores[det])
        track.detection_box = now.boxes[det].copy()
        track.last_frame = now.frame
        track.hits += 1
        if track.state is not TrackState.CONFIRMED:
            track.state = TrackState.CONFIRMED
        if track.track_id is None:
            track.track_id = self._take_id()

    def _new_track(self, det: int, now: _Frame[P], confirmed: bool) -> Track[P]:
        mean, cov = self.kalman.initiate(now.measurements[det : det + 1])
        return Track(
            track_id=self._take_id() if confirmed else None,
            state=TrackState.CONFIRMED if confirmed else TrackState.TENTATIVE,
            mean=mean[0],
            covariance=cov[0],
            payload=now.payloads[det],
            score=float(now.scores[det]),
            detection_box=now.boxes[det].copy(),
            start_frame=now.frame,
            last_frame=now.frame,
            key=self._take_key(),
        )

    def _take_key(self) -> int:
        key = self._next_key
        self._next_key += 1
        return key

    def _take_id(self) -> int:
        track_id = self._next_id
        self._next_id += 1
        return track_id

    def _remove_duplicates(self, frame: int) -> None:
        active = [t for t in self._tracks
                  if t.state in (TrackState.CONFIRMED, TrackState.TENTATIVE)
                  and t.last_frame == frame]
        lost = [t for t in self._tracks if t.state is TrackState.LOST]
        if not active or not lost:
            return
        overlap = box_iou(np.stack([t.box for t in active]), np.stack([t.box for t in lost]))
        for i, j in zip(*np.nonzero(overlap > self.config.duplicate_iou), strict=True):
            a, b = active[i], lost[j]
            # The longer-lived track survives (ties remove the active one, as the code does).
            if a.last_frame - a.start_frame > b.last_frame - b.start_frame:
                b.state = TrackState.REMOVED
            else:
                a.state = TrackState.REMOVED

    def _outputs(self, matched_det: dict[int, Track[P]], frame: int) -> list[TrackOutput]:
        cfg = self.config
        out = []
        for det, track in matched_det.items():
            if track.state is not TrackState.CONFIRMED or track.last_frame != frame:
                continue
            assert track.track_id is not None
            box = track.box if cfg.report_filtered_box else track.detection_box.copy()
            if not (np.all(np.isfinite(box)) and box[2] > 0 and box[3] > 0):
                box = track.detection_box.copy()  # a degenerate filter state; never seen
            w, h = box[2], box[3]
            if cfg.output_min_area is not None and not w * h > cfg.output_min_area:
                continue
            if cfg.output_max_aspect is not None and not w / h <= cfg.output_max_aspect:
                continue
            out.append(TrackOutput(track.track_id, box, track.score, det))
        out.sort(key=lambda o: o.track_id)
        return out


def _unambiguous(cost: np.ndarray, matches: np.ndarray, threshold: float,
                 margin: float) -> np.ndarray:
    """Keep the matches whose rival pairs (same row or column) all cost at least ``margin`` more."""
    keep = []
    for row, col in matches:
        alternatives = np.concatenate([np.delete(cost[row], col), np.delete(cost[:, col], row)])
        alternatives = alternatives[alternatives < threshold]
        keep.append(not len(alternatives) or alternatives.min() - cost[row, col] >= margin)
    return matches[np.asarray(keep, dtype=bool)]


def _to_numpy(values: Any) -> np.ndarray:
    """Convert a similarity result (numpy array, torch tensor, nested list) to float64."""
    if hasattr(values, "detach"):
        values = values.detach().cpu().numpy()
    return np.asarray(values, dtype=np.float64)
