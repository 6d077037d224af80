"""DAVIS video object segmentation metrics: J, F and J&F.

Label maps are ``(H, W)`` integer arrays: 0 = background, ``k`` = object ``k``, 255 = void.
Object ``k`` of the prediction is scored against object ``k`` of the ground truth (no
matching). The definitions (for users: docs/evaluation.md) are those of
davisvideochallenge/davis2017-evaluation, ``davis2017/metrics.py`` and ``evaluation.py``:
decay bins are cut at ``round(linspace(1, n, 5))``, the semi-supervised evaluation drops the
first and last frames (``all_gt_masks[:, 1:-1]``), and J&F-Mean averages J-mean and F-mean
over all objects of all sequences, not per sequence first. TrackEval 1.3.0's ``JAndF``
(``trackeval/metrics/j_and_f.py``) has the same J and F (the tests compare its
``_compute_j``/``_compute_f``) but matches ids with the Hungarian algorithm, keeps the first
and last frames and has no void label, hence this implementation.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

DAVIS_VOID_LABEL: int = 255
"""Label of "void" pixels (object borders, ambiguous regions) excluded from J and F."""

BOUNDARY_THRESHOLD: float = 0.008
"""DAVIS ``bound_th``: boundary tolerance as a fraction of the image diagonal (< 1), or in
pixels when >= 1."""

RECALL_THRESHOLD: float = 0.5
"""A frame counts towards J-recall / F-recall when its value is strictly above this."""

DECAY_BINS: int = 4
"""Number of temporal bins for the decay statistic (first bin minus last bin)."""


def _as_mask(mask: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(mask)
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a 2-D (H, W) mask; got shape {arr.shape}")
    return arr.astype(bool)


def region_similarity(
    gt_mask: np.ndarray, pred_mask: np.ndarray, void_mask: np.ndarray | None = None
) -> float:
    """Return J, the IoU of two ``(H, W)`` masks outside void pixels; 1.0 when both are empty.

    >>> region_similarity(np.eye(2, dtype=bool), np.ones((2, 2), dtype=bool))
    0.5
    """
    g = _as_mask(gt_mask, "gt_mask")
    p = _as_mask(pred_mask, "pred_mask")
    if g.shape != p.shape:
        raise ValueError(f"gt_mask {g.shape} and pred_mask {p.shape} differ in shape")
    keep = np.ones_like(g) if void_mask is None else ~_as_mask(void_mask, "void_mask")
    if keep.shape != g.shape:
        raise ValueError(f"void_mask {keep.shape} and gt_mask {g.shape} differ in shape")
    inter = int(np.count_nonzero(g & p & keep))
    union = int(np.count_nonzero((g | p) & keep))
    if union == 0:
        return 1.0
    return inter / union


def boundary_map(mask: np.ndarray) -> np.ndarray:
    """Return the one-pixel-wide boundary of a binary mask (DAVIS ``seg2bmap``, same size).

    A pixel is on the boundary when it differs from its right, lower or lower-right
    neighbour; the image border itself is not a boundary.

    >>> boundary_map(np.array([[0, 0, 0], [0, 1, 0], [0, 0, 0]])).astype(int)
    array([[1, 1, 0],
           [1, 1, 0],
           [0, 0, 0]])
    """
    seg = _as_mask(mask, "mask")
    padded = np.pad(seg, ((0, 1), (0, 1)), mode="edge")
    right = padded[:-1, 1:]
    below = padded[1:, :-1]
    below_right = padded[1:, 1:]
    return (seg ^ right) | (seg ^ below) | (seg ^ below_right)


def disk_footprint(radius: float) -> np.ndarray:
    """Return the ``uint8`` disk ``x**2 + y**2 <= radius**2`` (``skimage``'s ``disk``)."""
    r = int(radius)
    if r < 0 or r != radius:
        raise ValueError(f"disk radius must be a non-negative whole number; got {radius}")
    offsets = np.arange(-r, r + 1)
    return (offsets[None, :] ** 2 + offsets[:, None] ** 2 <= r * r).astype(np.uint8)


def boundary_tolerance_px(shape: tuple[int, int], bound_th: float = BOUNDARY_THRESHOLD) -> int:
    """Return the DAVIS boundary tolerance in pixels for an image of ``shape`` ``(H, W)``."""
    if bound_th >= 1:
        return int(bound_th)
    return int(math.ceil(bound_th * math.hypot(shape[0], shape[1])))


def boundary_measure(
    gt_mask: np.ndarray,
    pred_mask: np.ndarray,
    void_mask: np.ndarray | None = None,
    bound_th: float = BOUNDARY_THRESHOLD,
) -> float:
    """Return F, the boundary F-measure in ``[0, 1]``; void pixels are removed first.

    ``bound_th`` is a fraction of the image diagonal (< 1) or pixels (>= 1).
    """
    g = _as_mask(gt_mask, "gt_mask")
    p = _as_mask(pred_mask, "pred_mask")
    if g.shape != p.shape:
        raise ValueError(f"gt_mask {g.shape} and pred_mask {p.shape} differ in shape")
    if void_mask is not None:
        keep = ~_as_mask(void_mask, "void_mask")
        g, p = g & keep, p & keep
    disk = disk_footprint(boundary_tolerance_px(g.shape, bound_th))
    pred_b = boundary_map(p)
    gt_b = boundary_map(g)
    n_pred = int(np.count_nonzero(pred_b))
    n_gt = int(np.count_nonzero(gt_b))
    if n_pred == 0 and n_gt == 0:
        precision, recall = 1.0, 1.0
    elif n_pred == 0:
        precision, recall = 1.0, 0.0
    elif n_gt == 0:
        precision, recall = 0.0, 1.0
    else:
        pred_near = cv2.dilate(pred_b.astype(np.uint8), disk).astype(bool)
        gt_near = cv2.dilate(gt_b.astype(np.uint8), disk).astype(bool)
        precision = np.count_nonzero(pred_b & gt_near) / n_pred
        recall = np.count_nonzero(gt_b & pred_near) / n_gt
    if precision + recall == 0:
        return 0.0
    return 2.0 * precision * recall / (precision + recall)


def _check_labels(gt: np.ndarray, pred: np.ndarray, object_ids: Sequence[int]) -> None:
    if gt.shape != pred.shape:
        raise ValueError(f"ground truth {gt.shape} and prediction {pred.shape} differ in shape")
    allowed = np.array([0, *object_ids])
    extra = np.setdiff1d(np.unique(pred), allowed)
    if len(extra):
        raise ValueError(
            f"prediction contains labels {extra.tolist()} that are not objects of the "
            f"sequence (objects: {list(object_ids)}; 0 = background)"
        )


def frame_scores(
    gt_labels: np.ndarray,
    pred_labels: np.ndarray,
    object_ids: Sequence[int],
    *,
    with_f: bool = True,
    void_label: int = DAVIS_VOID_LABEL,
    bound_th: float = BOUNDARY_THRESHOLD,
) -> tuple[np.ndarray, np.ndarray]:
    """Return per-object ``(j, f)`` of one frame; F is NaN unless ``with_f`` (slower).

    Raises ValueError when shapes differ or the prediction uses a label that is not an object.
    """
    gt = np.asarray(gt_labels)
    pred = np.asarray(pred_labels)
    _check_labels(gt, pred, object_ids)
    void = gt == void_label
    j = np.empty(len(object_ids))
    f = np.full(len(object_ids), np.nan)
    for k, obj in enumerate(object_ids):
        g, p = gt == obj, pred == obj
        j[k] = region_similarity(g, p, void)
        if with_f:
            f[k] = boundary_measure(g, p, void, bound_th)
    return j, f


def frame_j(gt_labels: np.ndarray, pred_labels: np.ndarray, object_ids: Sequence[int]) -> float:
    """Return the mean J over the objects of one frame (the VOS per-step reward)."""
    j, _ = frame_scores(gt_labels, pred_labels, object_ids, with_f=False)
    return float(j.mean()) if len(j) else 1.0


def davis_statistics(per_frame: np.ndarray) -> tuple[float, float, float]:
    """Return ``(mean, recall, decay)`` of one object's per-frame J or F (DAVIS).

    ``mean`` ignores NaN frames; decay = mean(first bin) - mean(last bin), bins sharing
    their edge frame as in the official code.
    """
    v = np.asarray(per_frame, dtype=np.float64).reshape(-1)
    if len(v) == 0:
        return float("nan"), float("nan"), float("nan")
    edges = (np.round(np.linspace(1, len(v), DECAY_BINS + 1) + 1e-10) - 1).astype(int)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", category=RuntimeWarning)  # all-NaN slices -> NaN
        mean = float(np.nanmean(v))
        # As in the official code, NaN frames count as failures in the recall.
        recall = float(np.mean(v > RECALL_THRESHOLD))
        first = v[edges[0] : edges[1] + 1]
        last = v[edges[-2] : edges[-1] + 1]
        decay = float(np.nanmean(first) - np.nanmean(last))
    return mean, recall, decay


@dataclass(frozen=True)
class VOSScores:
    """DAVIS scores of one sequence, or of several sequences pooled by object.

    Objects are named ``"<sequence>_<id>"``; ``j_per_frame``/``f_per_frame`` hold one
    array per object over the scored frames; the other arrays are per-object statistics.
    """

    object_names: tuple[str, ...]
    j_per_frame: tuple[np.ndarray, ...]
    f_per_frame: tuple[np.ndarray, ...]
    j_mean: np.ndarray
    j_recall: np.ndarray
    j_decay: np.ndarray
    f_mean: np.ndarray
    f_recall: np.ndarray
    f_decay: np.ndarray
    summary: dict[str, float] = field(init=False)

    def __post_init__(self) -> None:
        def avg(x: np.ndarray) -> float:
            return float(np.nanmean(x)) if np.any(~np.isnan(x)) else float("nan")

        s = {
            "J-Mean": avg(self.j_mean),
            "J-Recall": avg(self.j_recall),
            "J-Decay": avg(self.j_decay),
            "F-Mean": avg(self.f_mean),
            "F-Recall": avg(self.f_recall),
            "F-Decay": avg(self.f_decay),
        }
        s["J&F-Mean"] = (s["J-Mean"] + s["F-Mean"]) / 2.0
        object.__setattr__(self, "summary", s)

    @property
    def j_and_f(self) -> float:
        """(J-mean + F-mean) / 2 over all objects."""
        return self.summary["J&F-Mean"]

    @property
    def num_objects(self) -> int:
        """Number of objects scored."""
        return len(self.object_names)


def evaluate_vos_sequence(
    gt_labels: Sequence[np.ndarray] | np.ndarray,
    pred_labels: Sequence[np.ndarray] | np.ndarray,
    object_ids: Sequence[int],
    *,
    sequence_name: str = "sequence",
    exclude_first_last: bool = True,
    void_label: int = DAVIS_VOID_LABEL,
    bound_th: float = BOUNDARY_THRESHOLD,
) -> VOSScores:
    """Score one sequence with the DAVIS-2017 semi-supervised protocol.

    ``exclude_first_last`` drops the first and last frame as the official script does.
    """
    if len(gt_labels) != len(pred_labels):
        raise ValueError(
            f"{len(gt_labels)} ground-truth frames but {len(pred_labels)} predicted frames"
        )
    frames = range(1, len(gt_labels) - 1) if exclude_first_last else range(len(gt_labels))
    n_obj = len(object_ids)
    j = np.zeros((n_obj, len(frames)))
    f = np.zeros((n_obj, len(frames)))
    for col, t in enumerate(frames):
        j[:, col], f[:, col] = frame_scores(
            gt_labels[t], pred_labels[t], object_ids, void_label=void_label, bound_th=bound_th
        )
    return scores_from_frames(j, f, object_ids, sequence_name)


def aggregate_vos(scores: Sequence[VOSScores]) -> VOSScores:
    """Pool several sequences' scores by object, as the DAVIS data-set table does."""
    if len(scores) == 0:
        raise ValueError("no sequences to aggregate")

    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(s, name) for s in scores])

    return VOSScores(
        object_names=tuple(n for s in scores for n in s.object_names),
        j_per_frame=tuple(a for s in scores for a in s.j_per_frame),
        f_per_frame=tuple(a for s in scores for a in s.f_per_frame),
        j_mean=cat("j_mean"),
        j_recall=cat("j_recall"),
        j_decay=cat("j_decay"),
        f_mean=cat("f_mean"),
        f_recall=cat("f_recall"),
        f_decay=cat("f_decay"),
    )


def scores_from_frames(
    j: np.ndarray, f: np.ndarray, object_ids: Sequence[int], sequence_name: str
) -> VOSScores:
    """A sequence's DAVIS scores from ``(objects, frames)`` J and F of its scored frames."""
    n = len(object_ids)
    j_stats = np.array([davis_statistics(row) for row in j]).reshape(n, 3)
    f_stats = np.array([davis_statistics(row) for row in f]).reshape(n, 3)
    return VOSScores(
        object_names=tuple(f"{sequence_name}_{obj}" for obj in object_ids),
        j_per_frame=tuple(j),
        f_per_frame=tuple(f),
        j_mean=j_stats[:, 0], j_recall=j_stats[:, 1], j_decay=j_stats[:, 2],
        f_mean=f_stats[:, 0], f_recall=f_stats[:, 1], f_decay=f_stats[:, 2],
    )
