"""TAP-Vid point tracking metrics, implemented from the paper's definitions.

Doersch et al., "TAP-Vid: A Benchmark for Tracking Any Point in a Video" (NeurIPS 2022),
section 4. For every query and every *evaluated* frame (not the query frame; in ``"first"``
mode not the frames before it either):

- occlusion accuracy ``OA``: the fraction of evaluated (query, frame) pairs whose predicted
  occlusion flag equals the ground truth's;
- ``<δ^x`` at ``δ`` in 1, 2, 4, 8, 16 pixels: of the pairs visible in the ground truth, the
  fraction predicted closer than ``δ`` (whatever the predicted flag); ``delta_x_avg`` their
  mean;
- Jaccard at ``δ``: true positives (visible, predicted visible, closer than ``δ``) over true
  positives + false negatives (visible, not a true positive) + false positives (predicted
  visible but occluded in the ground truth, or farther than ``δ``); ``AJ`` their mean.

Distances are in pixels of the evaluation raster (:mod:`unitrack_env.metrics.point_queries`).
Every metric is computed per video; a data set's value is the mean over its videos. A ratio
whose denominator is 0 (``<δ^x`` of a video without an evaluated visible pair) is NaN, and
left out of that metric's mean.
"""

from __future__ import annotations

import numpy as np

from unitrack_env.metrics.point_queries import check_query_mode

THRESHOLDS: tuple[int, ...] = (1, 2, 4, 8, 16)
"""``δ`` of the position metrics, in raster pixels (the paper's)."""

COLUMNS: tuple[str, ...] = ("AJ", "delta_x_avg", "OA")
"""The headline metrics: average Jaccard, ``<δ^x_avg``, occlusion accuracy."""

METRIC_NAMES: tuple[str, ...] = (
    *COLUMNS, *(f"Jaccard@{d}" for d in THRESHOLDS), *(f"delta_x@{d}" for d in THRESHOLDS))
"""Every metric of a video, headline first."""


def evaluated_pairs(query_frames: np.ndarray, num_frames: int, mode: str) -> np.ndarray:
    """``(Q, T)`` bool: the (query, frame) pairs scored (query frame out; "first": earlier too)."""
    check_query_mode(mode)
    frames = np.arange(num_frames)[None, :]
    q = np.asarray(query_frames, np.int64)[:, None]
    return frames > q if mode == "first" else frames != q


def pair_counts(pred_tracks: np.ndarray, pred_occluded: np.ndarray, gt_tracks: np.ndarray,
                gt_occluded: np.ndarray, evaluated: np.ndarray,
                axis: int | tuple[int, ...] | None = None) -> dict[str, np.ndarray]:
    """The counts the metrics are ratios of, summed over ``axis`` of the ``(Q, T)`` pairs.

    ``evaluated`` ``(Q, T)`` bool (:func:`evaluated_pairs`); keys ``evaluated``,
    ``occlusion_correct``, ``visible`` and per threshold ``d``: ``within_d``, ``tp_d``,
    ``fp_d``.
    """
    pred_visible = ~np.asarray(pred_occluded, bool)
    visible = ~np.asarray(gt_occluded, bool) & evaluated
    distance2 = np.sum((np.asarray(pred_tracks, np.float64)
                        - np.asarray(gt_tracks, np.float64)) ** 2, axis=-1)
    counts = {
        "evaluated": evaluated.sum(axis=axis),
        "occlusion_correct": (evaluated & (pred_visible == ~np.asarray(gt_occluded, bool))
                              ).sum(axis=axis),
        "visible": visible.sum(axis=axis),
    }
    for d in THRESHOLDS:
        within = distance2 < d * d
        counts[f"within_{d}"] = (visible & within).sum(axis=axis)
        counts[f"tp_{d}"] = (visible & within & pred_visible).sum(axis=axis)
        counts[f"fp_{d}"] = (evaluated & pred_visible & ~(visible & within)).sum(axis=axis)
    return counts


def _ratio(numerator: float, denominator: float) -> float:
    return float(numerator) / float(denominator) if denominator > 0 else float("nan")


def metrics_from_counts(counts: dict[str, np.ndarray]) -> dict[str, float]:
    """The metrics (:data:`METRIC_NAMES`) of one video's summed counts."""
    out: dict[str, float] = {"OA": _ratio(counts["occlusion_correct"], counts["evaluated"])}
    for d in THRESHOLDS:
        out[f"delta_x@{d}"] = _ratio(counts[f"within_{d}"], counts["visible"])
        out[f"Jaccard@{d}"] = _ratio(counts[f"tp_{d}"], counts["visible"] + counts[f"fp_{d}"])
    out["AJ"] = float(np.mean([out[f"Jaccard@{d}"] for d in THRESHOLDS]))
    out["delta_x_avg"] = float(np.mean([out[f"delta_x@{d}"] for d in THRESHOLDS]))
    return {name: out[name] for name in METRIC_NAMES}


def video_metrics(query_points: np.ndarray, gt_tracks: np.ndarray, gt_occluded: np.ndarray,
                  pred_tracks: np.ndarray, pred_occluded: np.ndarray,
                  mode: str) -> dict[str, float]:
    """The TAP-Vid metrics of one video.

    ``query_points`` ``(Q, 3)`` (t, y, x); tracks ``(Q, T, 2)`` x, y in raster pixels;
    occlusion flags ``(Q, T)`` bool.
    """
    gt_occluded = np.asarray(gt_occluded, bool)
    evaluated = evaluated_pairs(np.asarray(query_points)[:, 0].astype(np.int64),
                                gt_occluded.shape[1], mode)
    return metrics_from_counts(pair_counts(pred_tracks, pred_occluded, gt_tracks, gt_occluded,
                                           evaluated))


def mean_over_videos(per_video: dict[str, dict[str, float]]) -> dict[str, float]:
    """Each metric's mean over the videos where it is defined (NaN where none is)."""
    out = {}
    for name in METRIC_NAMES:
        values = np.array([m[name] for m in per_video.values()], np.float64)
        values = values[~np.isnan(values)]
        out[name] = float(values.mean()) if len(values) else float("nan")
    return out


def frame_values(pred_tracks: np.ndarray, pred_occluded: np.ndarray, gt_tracks: np.ndarray,
                 gt_occluded: np.ndarray, evaluated: np.ndarray) -> dict[str, np.ndarray]:
    """Per-frame ``(T,)`` metrics of one video (timelines): ``AJ``, ``delta_x_avg``, ``OA``.

    Each is the video metric restricted to one frame's evaluated pairs (NaN where the frame
    has none).
    """
    counts = pair_counts(pred_tracks, pred_occluded, gt_tracks, gt_occluded, evaluated, axis=0)
    frames = len(counts["evaluated"])
    rows = [metrics_from_counts({k: v[t] for k, v in counts.items()}) for t in range(frames)]
    return {name: np.array([row[name] for row in rows]) for name in COLUMNS}


def frame_reward(pred_xy: np.ndarray, pred_occluded: np.ndarray, gt_xy: np.ndarray,
                 gt_occluded: np.ndarray) -> float:
    """One frame's ``<δ^x_avg`` over the given (evaluated) queries visible in the ground truth.

    ``(K, 2)`` positions and ``(K,)`` flags; 0.0 when no query is visible. The predicted flag
    does not count here (as in ``<δ^x``).
    """
    del pred_occluded  # the position metric ignores the flag by definition
    visible = ~np.asarray(gt_occluded, bool)
    if not visible.any():
        return 0.0
    distance2 = np.sum((np.asarray(pred_xy, np.float64)[visible]
                        - np.asarray(gt_xy, np.float64)[visible]) ** 2, axis=-1)
    return float(np.mean([np.mean(distance2 < d * d) for d in THRESHOLDS]))


def event_rows(pred_tracks: np.ndarray, pred_occluded: np.ndarray, gt_tracks: np.ndarray,
               gt_occluded: np.ndarray, evaluated: np.ndarray) -> list[dict[str, object]]:
    """One error-event row per evaluated (query, frame) pair, frame by frame.

    Keys: ``frame``, ``query``, ``error_px`` (distance to the ground truth; None where the
    point is occluded in the ground truth), ``visible`` (ground truth), ``predicted_visible``,
    ``occlusion_correct``, ``within`` (the smallest threshold it is within, 0 if none).
    """
    rows: list[dict[str, object]] = []
    error = np.sqrt(np.sum((np.asarray(pred_tracks, np.float64)
                            - np.asarray(gt_tracks, np.float64)) ** 2, axis=-1))
    gt_visible = ~np.asarray(gt_occluded, bool)
    pred_visible = ~np.asarray(pred_occluded, bool)
    for t in range(evaluated.shape[1]):
        for q in np.flatnonzero(evaluated[:, t]):
            visible = bool(gt_visible[q, t])
            passed = [d for d in THRESHOLDS if visible and error[q, t] < d]
            rows.append({"frame": t, "query": int(q),
                         "error_px": float(error[q, t]) if visible else None,
                         "visible": visible, "predicted_visible": bool(pred_visible[q, t]),
                         "occlusion_correct": bool(pred_visible[q, t] == visible),
                         "within": min(passed) if passed else 0})
    return rows
