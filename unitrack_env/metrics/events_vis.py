"""Per-frame error events of YouTube-VIS: what each track contributes to AP at IoU 0.50.

TrackEval's matching at IoU 0.50 types each result track ``tp``, ``fp`` (paired with the
ground truth it overlaps most) or ``ignored`` (a crowd match); unmatched ground truth gives
``fn``. Rows cover the frames where either side has a mask, with the frame's ``iou``, the
``score`` and the video-level ``track_iou``; AP50 follows from them.
"""

from __future__ import annotations

import numpy as np

from unitrack_env.datasets.rle import mask_api as mask_utils
from unitrack_env.datasets.youtube_vis import VisData, VisTrack, VisVideo
from unitrack_env.metrics.events_mot import EventRows
from unitrack_env.metrics.vis import track_matches


def _overlap(a: tuple, b: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame: intersection, union, and whether either track has a mask there."""
    n = len(a)
    inter, union, present = np.zeros(n), np.zeros(n), np.zeros(n, dtype=bool)
    for t in range(n):
        x, y = a[t], b[t] if t < len(b) else None
        present[t] = bool(x) or bool(y)
        if x and y:
            inter[t] = float(mask_utils.area(mask_utils.merge([x, y], intersect=True)))
            union[t] = float(mask_utils.area(mask_utils.merge([x, y], intersect=False)))
        elif x or y:
            union[t] = float(mask_utils.area(x or y))
    return inter, union, present


def _track_iou(inter: np.ndarray, union: np.ndarray) -> float:
    total = float(union.sum())
    return float(inter.sum()) / total if total > np.finfo(float).eps else 0.0


def gt_tracks(data: VisData, video: VisVideo) -> dict[int, VisTrack]:
    """The video's ground-truth tracks by annotation id (as written for TrackEval)."""
    return {(t.id if t.id >= 0 else k + 1): t for k, t in enumerate(data.tracks or ())
            if t.video_id == video.id}


def _add_track(rows: EventRows, kind: str, pred: VisTrack | None, gt: VisTrack | None,
               **ids: int) -> None:
    empty = (None,) * len((pred or gt).segmentations)
    a = pred.segmentations if pred is not None else empty
    inter, union, present = _overlap(a, gt.segmentations if gt is not None else empty)
    values = dict(ids, object=(pred or gt).category_id)
    if pred is not None:
        values["score"] = float(pred.score)
    if pred is not None and gt is not None:
        values["track_iou"] = _track_iou(inter, union)
    for t in np.flatnonzero(present).tolist():
        iou = inter[t] / union[t] if union[t] > 0 else 0.0
        rows.add(t + 1, kind, **values, **({"iou": iou} if "track_iou" in values else {}))


def _best_overlap(pred: VisTrack, candidates: dict[int, VisTrack]) -> int:
    """Annotation id of the candidate with the largest video IoU with ``pred`` (-1: none)."""
    best, best_iou = -1, 0.0
    for gt_id, gt in candidates.items():
        iou = _track_iou(*_overlap(pred.segmentations, gt.segmentations)[:2])
        if iou > best_iou:
            best, best_iou = gt_id, iou
    return best


def vis_sequence_events(sequence: str, data: VisData, results: list[VisTrack],
                        video: VisVideo) -> EventRows:
    """Events of one video's result tracks (see the module docstring).

    ``track_id`` is the 1-based position of the track in the video's results, ``gt_id`` the
    annotation id, ``object`` the category id.
    """
    results = [r for r in results if r.video_id == video.id]
    gts = gt_tracks(data, video)
    rows = EventRows(sequence)
    for match in track_matches(data, results, video):
        same_class = [g for g in match.gt_ids if g in gts]
        for index, gt_id, ignored in zip(match.dt_index, match.dt_gt, match.dt_ignored,
                                         strict=True):
            pred = results[index]
            kind = "ignored" if ignored else "tp" if gt_id >= 0 else "fp"
            if gt_id < 0:  # unmatched: compare with the ground truth it overlaps most
                gt_id = _best_overlap(pred, {g: gts[g] for g in same_class})
            extra = {"gt_id": gt_id} if gt_id >= 0 else {}
            _add_track(rows, kind, pred, gts.get(gt_id), track_id=index + 1, **extra)
        for gt_id, matched, ignored in zip(match.gt_ids, match.gt_matched, match.gt_ignored,
                                           strict=True):
            if not matched and not ignored:
                _add_track(rows, "fn", None, gts[gt_id], gt_id=gt_id)
    return rows
