"""Cross-check of MOTChallenge scores with py-motmetrics 1.4.0.

py-motmetrics (C. Heindl, J. Valmadre et al., https://github.com/cheind/py-motmetrics, MIT
licence) is an independent implementation of CLEAR MOT and the ID measures.  We feed it exactly
the frames TrackEval scores: each frame goes through our
:func:`~unitrack_env.metrics.mot_preprocess.preprocess_frame` (TrackEval's MOTChallenge
preprocessing) first, and the distance matrix is ``1 - IoU`` with pairs below ``0.5 - eps`` IoU
marked NaN (do not pair), the threshold TrackEval's CLEAR uses.  We pass our own distances
because motmetrics 1.4.0's ``iou_matrix`` calls ``np.asfarray``, which NumPy 2 removed; and we
compute on a single accumulator because ``merge_event_dataframes`` breaks on pandas 2.

Where the two libraries can legitimately differ (none of these happens on the real MOT17 clips
or PETS09-S2L1 with the perturbed trackers of our tests, where they agree exactly):

* Track continuation: motmetrics first keeps every gt-hypothesis pair that was matched at *any*
  earlier frame if it is still within the threshold; TrackEval only favours the pair matched in
  the *previous* timestep (via a score bonus).  After a gap in which a gt was missed, a better
  overlapping hypothesis can win in TrackEval but not in motmetrics.
* Assignment objective: motmetrics maximises the number of matches, then minimises the summed
  ``1 - IoU``; TrackEval maximises the summed IoU.  In crowded chains of boxes that all overlap
  by more than 0.5 the two can pick matchings of different size.
* IDF1: TrackEval's Identity metric counts pairs with ``IoU >= 0.5`` exactly; the accumulator
  here admits ``IoU >= 0.5 - eps`` (one unit in the last place of 0.5).
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
