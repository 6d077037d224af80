"""Single object tracking (SOT) metrics in the OTB toolkit's way: success AUC and precision.

``pred`` and ``gt`` are ``(n, 4)`` ``(x, y, w, h)`` boxes in the same pixel frame (OTB's is
1-based; a shared origin cancels out), row ``i`` = frame ``i``, row 0 = the initialisation
frame. The rules are the OTB-2015 toolkit's (``tracker_benchmark_v1.0``:
``util/calcSeqErrRobust.m``, ``perfPlot.m``/``OPE_perfmat.m``); visionml/pytracking's port
(``pytracking/analysis/extract_results.py``) agrees on frame 1, the thresholds and the
comparisons, and differs where said:

* Frame 1's prediction is the ground truth (``rectMat(1,:) = rect_anno(1,:)``); a later
  prediction that is NaN or has ``w <= 0`` or ``h <= 0`` is the previous one unless that
  frame's ground truth is NaN (pytracking repairs zero sizes only, rejects NaN or negative).
* The toolkit's overlap (``calcRectInt.m``: ``x2 = x + w - 1``, ``+1`` on the intersection
  side) is the continuous IoU of :func:`unitrack_env.geometry.box_iou` and TrackEval; its
  centre ``x + (w - 1) / 2`` gives the same centre errors as ``x + w / 2``.
* Ground truth is valid only when all four numbers are ``> 0`` (``rect_anno > 0``,
  ``sum(index, 2) == 4``; NaN compares false). Invalid frames get overlap and centre error
  ``-1`` and stay in the denominator (:data:`INVALID_GT_TOOLKIT`); pytracking drops them
  (valid = ``w > 0 and h > 0``: :data:`INVALID_GT_EXCLUDE`).
* Success counts overlaps ``> t``, precision centre errors ``<= d``; the toolkit divides by
  ``len + eps``, we by ``len``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

OTB_OVERLAP_THRESHOLDS: np.ndarray = np.linspace(0.0, 1.0, 21)
"""IoU thresholds of the OTB success plot, MATLAB ``0:0.05:1`` (21 values)."""
OTB_OVERLAP_THRESHOLDS.setflags(write=False)

OTB_CENTER_THRESHOLDS: np.ndarray = np.arange(0, 51, dtype=np.float64)
"""Centre-error thresholds of the OTB precision plot in pixels, MATLAB ``0:50``."""
OTB_CENTER_THRESHOLDS.setflags(write=False)

PRECISION_THRESHOLD_PX: float = 20.0
"""The precision plot's reported point: fraction of frames with centre error <= 20 px."""

NORM_PRECISION_THRESHOLDS: np.ndarray = np.arange(0, 51, dtype=np.float64) / 100.0
"""Thresholds of LaSOT's normalized precision plot, MATLAB ``(0:50) / 100``."""
NORM_PRECISION_THRESHOLDS.setflags(write=False)

NORM_PRECISION_THRESHOLD: float = 0.2
"""The normalized precision plot's reported point (LaSOT toolkit's ``rank_idx = 21``)."""

INVALID_GT_TOOLKIT = "toolkit"
"""Invalid ground truth as the OTB MATLAB toolkit treats it (see the module docstring)."""
INVALID_GT_EXCLUDE = "exclude"
"""Invalid ground truth (NaN, ``w <= 0`` or ``h <= 0``) removed from the evaluation."""

InvalidGTRule = Literal["toolkit", "exclude"]

_INVALID_SCORE = -1.0  # the toolkit's marker for frames without valid ground truth


def _as_boxes(boxes: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(boxes, dtype=np.float64)
    if arr.ndim == 1 and arr.shape == (4,):
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise ValueError(f"{name} must have shape (n, 4) as (x, y, w, h); got {arr.shape}")
    return arr


def _check_pair(pred: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    p = _as_boxes(pred, "pred")
    g = _as_boxes(gt, "gt")
    if p.shape != g.shape:
        raise ValueError(
            f"pred has {len(p)} boxes but gt has {len(g)}: give one prediction per frame"
        )
    return p, g


def overlap_per_frame(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Return the IoU of ``pred[i]`` with ``gt[i]`` for every row ``i``.

    Rows where either box is non-finite or has no area get 0; rounding never lifts a value
    above 1 (identical fractional boxes could read 1 + 1 ulp and pass the 1.0 threshold).

    >>> overlap_per_frame(np.array([[0, 0, 10, 10]]), np.array([[5, 0, 10, 10]]))
    array([0.33333333])
    """
    p, g = _check_pair(pred, gt)
    finite = np.isfinite(p).all(axis=1) & np.isfinite(g).all(axis=1)
    p = np.where(finite[:, None], p, 0.0)
    g = np.where(finite[:, None], g, 0.0)
    iw = np.minimum(p[:, 0] + p[:, 2], g[:, 0] + g[:, 2]) - np.maximum(p[:, 0], g[:, 0])
    ih = np.minimum(p[:, 1] + p[:, 3], g[:, 1] + g[:, 3]) - np.maximum(p[:, 1], g[:, 1])
    inter = np.clip(iw, 0.0, None) * np.clip(ih, 0.0, None)
    area_p = np.clip(p[:, 2], 0.0, None) * np.clip(p[:, 3], 0.0, None)
    area_g = np.clip(g[:, 2], 0.0, None) * np.clip(g[:, 3], 0.0, None)
    union = area_p + area_g - inter
    out = np.zeros(len(p))
    np.divide(inter, union, out=out, where=finite & (union > 0))
    return np.minimum(out, 1.0)


def center_error_per_frame(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Return the Euclidean distance in pixels between box centres, row by row.

    Rows with a non-finite number get ``inf``.

    >>> center_error_per_frame(np.array([[3, 4, 10, 10]]), np.array([[0, 0, 10, 10]]))
    array([5.])
    """
    p, g = _check_pair(pred, gt)
    dc = (p[:, :2] + p[:, 2:] / 2.0) - (g[:, :2] + g[:, 2:] / 2.0)
    err = np.hypot(dc[:, 0], dc[:, 1])
    err[~np.isfinite(err)] = np.inf
    return err


def normalized_center_error(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Centre distance with x divided by the true width and y by the true height (LaSOT).

    >>> normalized_center_error(np.array([[2, 0, 10, 10]]), np.array([[0, 0, 20, 10]]))
    array([0.15])
    """
    p, g = _check_pair(pred, gt)
    dc = (p[:, :2] + p[:, 2:] / 2.0) - (g[:, :2] + g[:, 2:] / 2.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        err = np.hypot(dc[:, 0] / g[:, 2], dc[:, 1] / g[:, 3])
    err[~np.isfinite(err)] = np.inf
    return err


def valid_ground_truth(gt: np.ndarray, rule: InvalidGTRule = INVALID_GT_TOOLKIT) -> np.ndarray:
    """Return which ground-truth rows count as annotated, as ``(n,)`` bool.

    ``"toolkit"``: all four numbers ``> 0`` (OTB MATLAB toolkit, so a box at ``x <= 0`` is
    invalid too); ``"exclude"``: finite with ``w > 0`` and ``h > 0`` (pytracking).
    """
    g = _as_boxes(gt, "gt")
    with np.errstate(invalid="ignore"):
        if rule == INVALID_GT_TOOLKIT:
            return np.all(g > 0, axis=1)
        if rule == INVALID_GT_EXCLUDE:
            return np.isfinite(g).all(axis=1) & (g[:, 2] > 0) & (g[:, 3] > 0)
    raise ValueError(f"unknown invalid_gt rule {rule!r}; use 'toolkit' or 'exclude'")


def frame_iou(pred_box: np.ndarray, gt_box: np.ndarray) -> float:
    """Return the IoU of one predicted box with one ground-truth box (a per-step reward).

    0.0 when the ground truth is missing or empty, so the value is always finite.
    """
    g = _as_boxes(gt_box, "gt_box")
    if not valid_ground_truth(g, INVALID_GT_EXCLUDE)[0]:
        return 0.0
    return float(overlap_per_frame(pred_box, g)[0])


def repair_predictions(
    pred: np.ndarray, gt: np.ndarray, *, init_from_gt: bool = True
) -> np.ndarray:
    """Apply the toolkit's clean-up of a result file before scoring.

    Frame 0 becomes the ground truth when ``init_from_gt``; afterwards a row that is
    non-finite or has ``w <= 0`` or ``h <= 0`` is replaced by the previous (repaired) row,
    unless that frame's ground truth contains NaN. Returns a new array.
    """
    p, g = _check_pair(pred, gt)
    p = p.copy()
    if len(p) == 0:
        return p
    if init_from_gt:
        p[0] = g[0]
    gt_has_nan = np.isnan(g).any(axis=1)
    for i in range(1, len(p)):
        bad = not np.isfinite(p[i]).all() or p[i, 2] <= 0 or p[i, 3] <= 0
        if bad and not gt_has_nan[i]:
            p[i] = p[i - 1]
    return p


def success_curve(
    overlaps: np.ndarray, thresholds: np.ndarray = OTB_OVERLAP_THRESHOLDS
) -> np.ndarray:
    """Return the fraction of frames whose overlap is strictly above each threshold.

    The toolkit's ``-1`` for invalid frames fails every threshold; NaN when there are no frames.
    """
    o = np.asarray(overlaps, dtype=np.float64).reshape(-1)
    if len(o) == 0:
        return np.full(len(thresholds), np.nan)
    return (o[:, None] > np.asarray(thresholds)[None, :]).mean(axis=0)


def precision_curve(
    center_errors: np.ndarray, thresholds: np.ndarray = OTB_CENTER_THRESHOLDS
) -> np.ndarray:
    """Return the fraction of frames whose centre error is ``<=`` each pixel threshold.

    The toolkit's ``-1`` for invalid frames passes every threshold.
    """
    e = np.asarray(center_errors, dtype=np.float64).reshape(-1)
    if len(e) == 0:
        return np.full(len(thresholds), np.nan)
    return (e[:, None] <= np.asarray(thresholds)[None, :]).mean(axis=0)


@dataclass(frozen=True)
class SOTScores:
    """Success and precision of one sequence (or the average over sequences).

    ``auc`` is the mean of ``success_curve`` (OTB's success score); ``average_overlap`` is
    over frames with valid ground truth; ``num_frames`` is the denominator.
    """

    success_curve: np.ndarray
    precision_curve: np.ndarray
    auc: float
    precision_20px: float
    average_overlap: float
    num_frames: int
    num_sequences: int = 1
    norm_precision_curve: np.ndarray | None = None

    @property
    def norm_precision(self) -> float | None:
        """Normalized precision at 0.2 (None unless it was computed)."""
        if self.norm_precision_curve is None:
            return None
        return _precision_at(self.norm_precision_curve, NORM_PRECISION_THRESHOLDS,
                             NORM_PRECISION_THRESHOLD)

    def as_dict(self) -> dict[str, float]:
        """Return the scalar metrics keyed by their report names (NormPrecision if computed)."""
        scores = {
            "AUC": self.auc,
            "Precision@20px": self.precision_20px,
            "AverageOverlap": self.average_overlap,
        }
        if self.norm_precision is not None:
            scores["NormPrecision"] = self.norm_precision
        return scores


def _precision_at(curve: np.ndarray, thresholds: np.ndarray, px: float) -> float:
    hit = np.flatnonzero(np.isclose(thresholds, px))
    if len(hit) == 0:
        raise ValueError(f"{px} px is not one of the precision thresholds")
    return float(curve[hit[0]])


def evaluate_sot_sequence(
    pred: np.ndarray,
    gt: np.ndarray,
    *,
    init_from_gt: bool = True,
    invalid_gt: InvalidGTRule = INVALID_GT_TOOLKIT,
    absent: np.ndarray | None = None,
    normalized: bool = False,
) -> SOTScores:
    """Score one sequence the way the OTB toolkit does (one-pass evaluation, OPE).

    ``init_from_gt`` replaces frame 0's prediction by the ground truth (toolkit default);
    ``invalid_gt`` is a :func:`valid_ground_truth` rule. ``absent`` (bool per frame) applies
    the LaSOT toolkit's rule: absent frames are removed before scoring but the rates stay
    divided by every frame, so an absent frame fails every threshold of both plots.
    ``normalized`` adds LaSOT's normalized precision curve.
    """
    p, g = _check_pair(pred, gt)
    if len(p) == 0:
        raise ValueError("cannot score an empty sequence")
    p = repair_predictions(p, g, init_from_gt=init_from_gt)
    valid = valid_ground_truth(g, invalid_gt)
    errors = {"ov": overlap_per_frame(p, g), "ce": center_error_per_frame(p, g)}
    if normalized:
        errors["nce"] = normalized_center_error(p, g)
    if invalid_gt == INVALID_GT_TOOLKIT:
        for values in errors.values():
            values[~valid] = _INVALID_SCORE
    else:
        errors = {k: v[valid] for k, v in errors.items()}
    gone = np.zeros(len(errors["ov"]), dtype=bool)
    if absent is not None:
        gone = np.asarray(absent, dtype=bool)
        gone = gone if invalid_gt == INVALID_GT_TOOLKIT else gone[valid]
    valid_overlaps = errors["ov"][(errors["ov"] >= 0) & ~gone]
    errors["ov"][gone] = _INVALID_SCORE
    for key in ("ce", "nce"):
        if key in errors:
            errors[key][gone] = np.inf
    p_curve = precision_curve(errors["ce"])
    s_curve = success_curve(errors["ov"])
    return SOTScores(
        success_curve=s_curve,
        precision_curve=p_curve,
        auc=float(np.mean(s_curve)),
        precision_20px=_precision_at(p_curve, OTB_CENTER_THRESHOLDS, PRECISION_THRESHOLD_PX),
        average_overlap=float(valid_overlaps.mean()) if len(valid_overlaps) else float("nan"),
        num_frames=len(errors["ov"]),
        norm_precision_curve=(precision_curve(errors["nce"], NORM_PRECISION_THRESHOLDS)
                              if normalized else None),
    )


def aggregate_sot(scores: Sequence[SOTScores]) -> SOTScores:
    """Average per-sequence scores with equal weight per sequence (OTB's overall plot).

    The AUC of the averaged curve equals the mean of the per-sequence AUCs.
    """
    if len(scores) == 0:
        raise ValueError("no sequences to aggregate")
    s_curve = np.mean([s.success_curve for s in scores], axis=0)
    p_curve = np.mean([s.precision_curve for s in scores], axis=0)
    norm = [s.norm_precision_curve for s in scores]
    return SOTScores(
        success_curve=s_curve,
        precision_curve=p_curve,
        auc=float(np.mean(s_curve)),
        precision_20px=_precision_at(p_curve, OTB_CENTER_THRESHOLDS, PRECISION_THRESHOLD_PX),
        average_overlap=float(np.nanmean([s.average_overlap for s in scores])),
        num_frames=int(sum(s.num_frames for s in scores)),
        num_sequences=int(sum(s.num_sequences for s in scores)),
        norm_precision_curve=(None if any(c is None for c in norm)
                              else np.mean(norm, axis=0)),
    )


GOT10K_SUCCESS_THRESHOLDS: tuple[float, float] = (0.5, 0.75)
"""GOT-10k's success rates: the fraction of frames whose overlap is above 0.5 and 0.75."""


def bounded_overlap(pred: np.ndarray, gt: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """IoU after clipping both boxes to the ``(width, height)`` image (the GOT-10k toolkit's).

    ``x`` and ``y`` are clipped to ``[0, width]`` / ``[0, height]``, then ``w`` / ``h`` to
    what remains of the image to their right / below.
    """
    width, height = image_size
    boxes = []
    for b in _check_pair(pred, gt):
        b = b.copy()
        b[:, 0] = np.clip(b[:, 0], 0, width)
        b[:, 1] = np.clip(b[:, 1], 0, height)
        b[:, 2] = np.clip(b[:, 2], 0, width - b[:, 0])
        b[:, 3] = np.clip(b[:, 3], 0, height - b[:, 1])
        boxes.append(b)
    return overlap_per_frame(*boxes)


def got10k_overlaps(pred: np.ndarray, gt: np.ndarray, cover: np.ndarray,
                    image_size: tuple[int, int]) -> np.ndarray:
    """The overlaps GOT-10k scores in one run of a sequence.

    Frames after the first whose ``cover.label`` is above 0 (the target visible), with both
    boxes clipped to the image.
    """
    p, g = _check_pair(pred, gt)
    visible = np.asarray(cover)[1:] > 0
    if len(visible) != len(p) - 1:
        raise ValueError(f"cover has {len(visible) + 1} labels but there are {len(p)} frames")
    return bounded_overlap(p[1:], g[1:], image_size)[visible]


def got10k_scores(overlaps: np.ndarray) -> dict[str, float]:
    """AO, SR0.5 and SR0.75 of the overlaps of every scored frame.

    GOT-10k pools the frames of all sequences and repetitions: pass their concatenation
    for the overall score.
    """
    o = np.asarray(overlaps, dtype=np.float64).reshape(-1)
    if len(o) == 0:
        raise ValueError("no frame with a visible target to score")
    scores = {"AO": float(o.mean())}
    for threshold in GOT10K_SUCCESS_THRESHOLDS:
        scores[f"SR{threshold:g}"] = float(np.mean(o > threshold))
    return scores
