"""Cross-check of MOTChallenge scores with py-motmetrics 1.4.0.

More in docs/module-notes.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from unitrack_env.metrics.mot_preprocess import (
    EPS,
    MATCH_IOU_THRESHOLD,
    GtFrame,
    TrackerFrame,
    preprocess,
)

#: motmetrics metric names we compute, and the TrackEval-style keys we return them under.
MOTMETRICS_FIELDS: dict[str, str] = {
    "mota": "MOTA",
    "motp": "MOTP_distance",
    "idf1": "IDF1",
    "idp": "IDP",
    "idr": "IDR",
    "num_switches": "IDSW",
    "num_false_positives": "CLR_FP",
    "num_misses": "CLR_FN",
    "num_detections": "CLR_TP",
    "num_objects": "GT_Dets",
    "num_predictions": "Dets",
    "idtp": "IDTP",
    "idfp": "IDFP",
    "idfn": "IDFN",
}


def _import_motmetrics() -> Any:
    try:
        import motmetrics
    except ImportError as exc:  # pragma: no cover - motmetrics is a core dependency
        raise ImportError(
            "the py-motmetrics cross-check needs `motmetrics` (pip install 'motmetrics>=1.4')"
        ) from exc
    return motmetrics


def iou_distance(iou: np.ndarray, threshold: float = MATCH_IOU_THRESHOLD) -> np.ndarray:
    """Return motmetrics distances ``1 - IoU``, NaN where ``IoU < threshold - eps`` (not pairable).

    >>> iou_distance(np.array([[0.75, 0.2]]))
    array([[0.25,  nan]])
    """
    iou = np.asarray(iou, dtype=np.float64)
    dist = 1.0 - iou
    dist[iou < threshold - EPS] = np.nan
    return dist


def motmetrics_summary(
    gt_frames: Sequence[GtFrame],
    tracker_frames: Sequence[TrackerFrame],
    *,
    benchmark: str,
) -> dict[str, float]:
    """Score a sequence with py-motmetrics after MOTChallenge preprocessing.

    Args:
        gt_frames: per-frame ground truth, frame ``t`` at index ``t - 1`` (see
            :func:`~unitrack_env.metrics.mot_preprocess.gt_frames_from_rows`).
        tracker_frames: per-frame tracker output, same length (see
            :func:`~unitrack_env.metrics.mot_preprocess.tracker_frames_from_rows`).
        benchmark: TrackEval benchmark name, deciding the preprocessing.

    Returns:
        ``{"MOTA", "IDF1", "IDP", "IDR", "IDSW", "CLR_TP", "CLR_FP", "CLR_FN", "GT_Dets",
        "Dets", "IDTP", "IDFP", "IDFN", "MOTP_distance"}`` as floats (fractions, not percent;
        ``MOTP_distance`` is motmetrics' mean ``1 - IoU``, i.e. ``1 - `` TrackEval's MOTP).
    """
    if len(gt_frames) != len(tracker_frames):
        raise ValueError(
            f"{len(gt_frames)} ground-truth frames but {len(tracker_frames)} tracker frames"
        )
    mm = _import_motmetrics()
    acc = mm.MOTAccumulator(auto_id=False)
    for t, (gt, trk) in enumerate(zip(gt_frames, tracker_frames, strict=True), start=1):
        frame = preprocess(gt, trk, benchmark)
        acc.update(
            frame.gt_ids.tolist(),
            frame.tracker_ids.tolist(),
            iou_distance(frame.iou),
            frameid=t,
        )
    host = mm.metrics.create()
    summary = host.compute(acc, metrics=list(MOTMETRICS_FIELDS), return_dataframe=False)
    return {key: float(summary[name]) for name, key in MOTMETRICS_FIELDS.items()}
