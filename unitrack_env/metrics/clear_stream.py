"""CLEAR MOT counts frame by frame, with TrackEval 1.3.0's matching (our own implementation).

Restates ``trackeval/metrics/clear.py`` (``CLEAR.eval_sequence``; the metrics are Bernardin &
Stiefelhagen's, EURASIP JIVP 2008). In a frame with both ground truth and tracker boxes the
score is ``1000 * [track id == the one this gt matched at the previous timestep] + IoU``,
zeroed below ``0.5 - eps``; the Hungarian assignment maximises it and pairs scoring ``<= eps``
are no match, so continuing a track beats any IoU gain. An ID switch is a match whose track
differs from the one its gt was *last* matched to, however many frames ago. A frame without
ground truth or without tracker boxes leaves the previous-timestep record untouched, as
TrackEval's early ``continue`` does. Summed over a sequence, ``tp``/``fp``/``fn``/``idsw``
equal TrackEval's ``CLR_TP``/``CLR_FP``/``CLR_FN``/``IDSW`` on the same preprocessed frames.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from unitrack_env.geometry import box_iou
from unitrack_env.metrics.mot_preprocess import (
    EPS,
    MATCH_IOU_THRESHOLD,
    GtFrame,
    TrackerFrame,
    preprocess,
)

#: Score bonus for continuing the previous timestep's match (TrackEval's constant).
CONTINUITY_BONUS: float = 1000.0


@dataclass(frozen=True)
class FrameClear:
    """CLEAR counts of one frame; ``iou_sum`` is the matches' summed IoU (MOTP's numerator)."""

    tp: int
    fp: int
    fn: int
    idsw: int
    iou_sum: float = 0.0

    @property
    def mota_numerator(self) -> int:
        """``tp - fp - idsw``: this frame's share of MOTA's numerator (the env's reward)."""
        return self.tp - self.fp - self.idsw


@dataclass
class ClearTotals:
    """Running sums of :class:`FrameClear` over a sequence."""

    tp: int = 0
    fp: int = 0
    fn: int = 0
    idsw: int = 0
    iou_sum: float = 0.0
    frames: int = 0

    def add(self, frame: FrameClear) -> None:
        """Add one frame's counts."""
        self.tp += frame.tp
        self.fp += frame.fp
        self.fn += frame.fn
        self.idsw += frame.idsw
        self.iou_sum += frame.iou_sum
        self.frames += 1

    @property
    def num_gt(self) -> int:
        """Evaluated ground-truth boxes (``tp + fn``)."""
        return self.tp + self.fn

    @property
    def mota(self) -> float:
        """``(tp - fp - idsw) / max(1, tp + fn)``, as TrackEval computes MOTA."""
        return (self.tp - self.fp - self.idsw) / max(1, self.num_gt)

    @property
    def motp(self) -> float:
        """Mean IoU of the matches, ``iou_sum / max(1, tp)`` (TrackEval's MOTP)."""
        return self.iou_sum / max(1, self.tp)


@dataclass
class StreamingClear:
    """TrackEval CLEAR matching applied one frame at a time.

    :meth:`reset` starts a new sequence; frames must already be preprocessed
    (:func:`~unitrack_env.metrics.mot_preprocess.preprocess_frame`).

    >>> clear = StreamingClear()
    >>> box = np.array([[0.0, 0.0, 10.0, 10.0]])
    >>> clear.update(np.array([1]), box, np.array([7]), box)
    FrameClear(tp=1, fp=0, fn=0, idsw=0, iou_sum=1.0)
    >>> clear.update(np.array([1]), box, np.array([8]), box).idsw
    1
    """

    threshold: float = MATCH_IOU_THRESHOLD
    totals: ClearTotals = field(default_factory=ClearTotals, init=False)
    _last_match: dict[int, int] = field(default_factory=dict, init=False, repr=False)
    _prev_step_match: dict[int, int] = field(default_factory=dict, init=False, repr=False)
    #: Matches of the last frame with ground truth and tracker boxes, gt id -> tracker id
    #: (the previous-frame record; read by the py-motmetrics cross-check).
    frame_matches: dict[int, int] = field(default_factory=dict, init=False, repr=False)
    #: ``(gt rows, tracker columns)`` matched in the last :meth:`update` (indices into its
    #: inputs), for per-frame error events (:mod:`unitrack_env.metrics.events_mot`).
    last_match: tuple[np.ndarray, np.ndarray] = field(
        default_factory=lambda: (np.zeros(0, np.int64), np.zeros(0, np.int64)), init=False,
        repr=False)

    def reset(self) -> None:
        """Forget all matches and totals (start of a sequence)."""
        self.totals = ClearTotals()
        self._last_match = {}
        self._prev_step_match = {}

    def update(
        self,
        gt_ids: np.ndarray,
        gt_boxes: np.ndarray,
        tracker_ids: np.ndarray,
        tracker_boxes: np.ndarray,
        *,
        iou: np.ndarray | None = None,
    ) -> FrameClear:
        """Score one preprocessed frame, add its counts to ``totals`` and return them.

        ``iou`` is an optional precomputed ``(n, k)`` IoU matrix (e.g. from preprocessing).
        """
        g_ids = np.asarray(gt_ids, dtype=np.int64).reshape(-1)
        t_ids = np.asarray(tracker_ids, dtype=np.int64).reshape(-1)
        n, k = len(g_ids), len(t_ids)
        self.last_match = (np.zeros(0, np.int64), np.zeros(0, np.int64))
        if n == 0 or k == 0:
            result = FrameClear(tp=0, fp=k, fn=n, idsw=0)
            self.totals.add(result)
            return result

        sim = box_iou(gt_boxes, tracker_boxes) if iou is None else np.asarray(iou, np.float64)
        if sim.shape != (n, k):
            raise ValueError(f"IoU matrix has shape {sim.shape}, expected {(n, k)}")
        prev = np.array([self._prev_step_match.get(int(g), -1) for g in g_ids], dtype=np.int64)
        has_prev = np.array([int(g) in self._prev_step_match for g in g_ids], dtype=bool)
        continues = has_prev[:, None] & (t_ids[None, :] == prev[:, None])
        score = CONTINUITY_BONUS * continues + sim
        score[sim < self.threshold - EPS] = 0.0
        rows, cols = linear_sum_assignment(-score)
        matched = score[rows, cols] > EPS
        rows, cols = self.last_match = rows[matched], cols[matched]

        idsw = 0
        for g, t in zip(g_ids[rows].tolist(), t_ids[cols].tolist(), strict=True):
            last = self._last_match.get(g)
            if last is not None and last != t:
                idsw += 1
            self._last_match[g] = t
        self.frame_matches = self._prev_step_match = dict(
            zip(g_ids[rows].tolist(), t_ids[cols].tolist(), strict=True))

        tp = len(rows)
        result = FrameClear(tp=tp, fp=k - tp, fn=n - tp, idsw=idsw,
                            iou_sum=float(sim[rows, cols].sum()) if tp else 0.0)
        self.totals.add(result)
        return result


def clear_from_frames(
    gt_frames: Sequence[GtFrame],
    tracker_frames: Sequence[TrackerFrame],
    *,
    benchmark: str,
) -> ClearTotals:
    """Preprocess and score a whole sequence frame by frame (frame ``t`` at index ``t - 1``)."""
    if len(gt_frames) != len(tracker_frames):
        raise ValueError(
            f"{len(gt_frames)} ground-truth frames but {len(tracker_frames)} tracker frames"
        )
    clear = StreamingClear()
    for gt, trk in zip(gt_frames, tracker_frames, strict=True):
        frame = preprocess(gt, trk, benchmark)
        clear.update(
            frame.gt_ids, frame.gt_boxes, frame.tracker_ids, frame.tracker_boxes, iou=frame.iou
        )
    return clear.totals
