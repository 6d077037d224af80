"""PCK (percentage of correct keypoints) for pose propagation on JHMDB.

Keypoints are ``(..., J, 2)`` ``(x, y)`` pixels, prediction and ground truth in the same frame.
A joint is correct when ``||pred - gt|| <= alpha * s``, ``s`` the frame's normaliser, computed
from the *ground-truth* joints. The default ``"box_diagonal"`` is the UniTrack JHMDB script's
(a copy of the CRW / TimeCycle ``eval_pck``: ``now_boxes[k] = 0.6 * norm([maxx, maxy] - [minx,
miny])``), which made the paper's JHMDB table (TimeCycle 57.3/78.1, UVC 58.6/79.6, CRW
59.0/83.2, I18 58.3/80.5 at PCK@0.1/0.2). ``"box_max_side"`` is the alternative commented out
there, the usual "person size" convention (Jhuang et al. 2013 use the person box; with joints
only, the joint box). As that script, :class:`PCKCounts` skips the given first frame, pools
each joint over all frames of all videos and reports the mean over the 15 joints; unlike it,
it keeps joints predicted at a negative x (docs/evaluation.md).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Literal

import numpy as np

PAPER_PCK_THRESHOLDS: tuple[float, ...] = (0.1, 0.2)
"""The ``alpha`` values of the paper's JHMDB table (PCK@0.1 and PCK@0.2)."""


BOX_DIAGONAL_FACTOR: float = 0.6
"""Factor on the GT joint-box diagonal in the default normaliser (UniTrack/CRW script)."""

Normaliser = Literal["box_diagonal", "box_max_side"]
NORMALISERS: tuple[str, ...] = ("box_diagonal", "box_max_side")


@contextmanager
def _quiet_nan_warnings() -> Iterator[None]:
    """Silence numpy's "All-NaN slice" / "Mean of empty slice" warnings in a block."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", category=RuntimeWarning)
        yield


def _as_keypoints(kp: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(kp, dtype=np.float64)
    if arr.ndim < 2 or arr.shape[-1] != 2:
        raise ValueError(f"{name} must have shape (..., J, 2) as (x, y); got {arr.shape}")
    return arr


def pck_normaliser(
    gt: np.ndarray,
    method: Normaliser = "box_diagonal",
    visible: np.ndarray | None = None,
) -> np.ndarray:
    """Return each frame's PCK normaliser in pixels (NaN without visible joints).

    ``"box_diagonal"`` is 0.6 x the visible joints' box diagonal; ``"box_max_side"`` its
    longer side.

    >>> float(pck_normaliser(np.array([[0.0, 0.0], [30.0, 40.0]])))
    30.0
    """
    g = _as_keypoints(gt, "gt")
    vis = np.ones(g.shape[:-1], dtype=bool) if visible is None else np.asarray(visible, bool)
    if vis.shape != g.shape[:-1]:
        raise ValueError(f"visible must have shape {g.shape[:-1]}; got {vis.shape}")
    xs = np.where(vis, g[..., 0], np.nan)
    ys = np.where(vis, g[..., 1], np.nan)
    with np.errstate(invalid="ignore"), _quiet_nan_warnings():
        w = np.nanmax(xs, axis=-1) - np.nanmin(xs, axis=-1)
        h = np.nanmax(ys, axis=-1) - np.nanmin(ys, axis=-1)
    if method == "box_diagonal":
        return BOX_DIAGONAL_FACTOR * np.hypot(w, h)
    if method == "box_max_side":
        return np.maximum(w, h)
    raise ValueError(f"unknown PCK normaliser {method!r}; choose one of {NORMALISERS}")


def keypoint_distances(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Return the ``(..., J)`` pixel distance of every predicted joint to its ground truth."""
    p = _as_keypoints(pred, "pred")
    g = _as_keypoints(gt, "gt")
    if p.shape != g.shape:
        raise ValueError(f"pred {p.shape} and gt {g.shape} differ in shape")
    d = p - g
    return np.hypot(d[..., 0], d[..., 1])


def frame_pck(
    pred: np.ndarray,
    gt: np.ndarray,
    alpha: float = 0.1,
    method: Normaliser = "box_diagonal",
    visible: np.ndarray | None = None,
) -> float:
    """Return the fraction of a frame's (visible) joints within ``alpha x normaliser``.

    The pose-propagation per-step reward; 0.0 when no joint is visible.

    >>> gt = np.array([[0.0, 0.0], [30.0, 40.0]])  # normaliser 0.6 * 50 = 30 px
    >>> frame_pck(gt + [[2.0, 0.0], [4.0, 0.0]], gt, alpha=0.1)  # 2 <= 3 < 4
    0.5
    """
    p = _as_keypoints(pred, "pred")
    g = _as_keypoints(gt, "gt")
    if p.ndim != 2 or g.shape != p.shape:
        raise ValueError(f"pred and gt must both be (J, 2); got {p.shape} and {g.shape}")
    vis = np.ones(len(g), dtype=bool) if visible is None else np.asarray(visible, bool)
    if not vis.any():
        return 0.0
    norm = pck_normaliser(g, method, vis)
    correct = keypoint_distances(p, g) <= alpha * norm
    return float(np.count_nonzero(correct & vis) / np.count_nonzero(vis))


@dataclass(frozen=True)
class PCKCounts:
    """Correct-joint counts ``(thresholds, J)`` and scored counts ``(J,)``, mergeable."""

    thresholds: tuple[float, ...]
    correct: np.ndarray
    total: np.ndarray

    def merge(self, other: PCKCounts) -> PCKCounts:
        """Return the pooled counts of two sets of videos (same thresholds and joints)."""
        if self.thresholds != other.thresholds or self.total.shape != other.total.shape:
            raise ValueError("cannot merge PCK counts with different thresholds or joints")
        return PCKCounts(self.thresholds, self.correct + other.correct, self.total + other.total)

    def per_joint(self) -> np.ndarray:
        """Return ``(len(thresholds), J)`` PCK per joint (NaN for a joint never scored)."""
        out = np.full(self.correct.shape, np.nan)
        np.divide(self.correct, self.total[None, :], out=out, where=self.total[None, :] > 0)
        return out

    def mean_over_joints(self) -> np.ndarray:
        """Return ``(len(thresholds),)`` PCK averaged over joints (the reported number)."""
        with _quiet_nan_warnings():
            return np.nanmean(self.per_joint(), axis=1)

    def as_dict(self) -> dict[str, float]:
        """Return ``{"PCK@0.1": ..., "PCK@0.2": ...}`` for every threshold."""
        values = self.mean_over_joints()
        return {f"PCK@{t:g}": float(v) for t, v in zip(self.thresholds, values, strict=True)}


def pck_counts(
    pred: np.ndarray,
    gt: np.ndarray,
    thresholds: Sequence[float] = PAPER_PCK_THRESHOLDS,
    *,
    method: Normaliser = "box_diagonal",
    skip_first_frame: bool = True,
    visible: np.ndarray | None = None,
) -> PCKCounts:
    """Count correct joints of one ``(T, J, 2)`` video at several thresholds.

    ``skip_first_frame`` leaves out frame 0 (it is given), as the authors' script does.
    """
    p = _as_keypoints(pred, "pred")
    g = _as_keypoints(gt, "gt")
    if p.ndim != 3 or p.shape != g.shape:
        raise ValueError(f"pred and gt must both be (T, J, 2); got {p.shape} and {g.shape}")
    vis = np.ones(g.shape[:2], dtype=bool) if visible is None else np.asarray(visible, bool)
    if vis.shape != g.shape[:2]:
        raise ValueError(f"visible must have shape {g.shape[:2]}; got {vis.shape}")
    start = 1 if skip_first_frame else 0
    p, g, vis = p[start:], g[start:], vis[start:]
    norm = pck_normaliser(g, method, vis)  # (T,)
    dist = keypoint_distances(p, g)  # (T, J)
    alphas = np.asarray(tuple(thresholds), dtype=np.float64)
    with np.errstate(invalid="ignore"):
        ok = dist[None, :, :] <= alphas[:, None, None] * norm[None, :, None]
    correct = np.count_nonzero(ok & vis[None], axis=1)
    return PCKCounts(tuple(float(t) for t in alphas), correct, np.count_nonzero(vis, axis=0))


def evaluate_pose_sequence(
    pred: np.ndarray,
    gt: np.ndarray,
    thresholds: Sequence[float] = PAPER_PCK_THRESHOLDS,
    *,
    method: Normaliser = "box_diagonal",
) -> dict[str, float]:
    """Return ``{"PCK@0.1": ..., "PCK@0.2": ...}`` of one video (frame 0 not scored)."""
    return pck_counts(pred, gt, thresholds, method=method).as_dict()
