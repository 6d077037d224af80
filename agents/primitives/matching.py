"""Assignment building blocks for association: thresholded Hungarian matching and costs.

Costs are ``(n_tracks, n_detections)`` arrays where lower is better; ``inf`` marks a pair
that may never be matched (e.g. gated out by the motion model).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from unitrack_env.geometry import box_iou

from .kalman import CHI2_95_4DOF

APPEARANCE_WEIGHT_PAPER = 0.99
"""Weight ``lambda`` of the appearance cost in the fused cost (paper, appendix C.1).

The fused cost is ``lambda * C_appearance + (1 - lambda) * C_motion``. The authors' MOT
configuration uses ``0.98`` instead (:data:`APPEARANCE_WEIGHT_CODE`).
"""

APPEARANCE_WEIGHT_CODE = 0.98
"""Weight ``lambda`` used by the authors' MOT configuration (paper says 0.99)."""


@dataclass(frozen=True)
class Assignment:
    """Result of a thresholded assignment between rows (tracks) and columns (detections).

    Attributes:
        matches: ``(k, 2)`` ``int64`` array of ``(row, column)`` pairs, sorted by row.
        unmatched_rows: ``int64`` indices of rows left unmatched, ascending.
        unmatched_cols: ``int64`` indices of columns left unmatched, ascending.
    """

    matches: np.ndarray
    unmatched_rows: np.ndarray
    unmatched_cols: np.ndarray


def linear_assignment(cost: np.ndarray, threshold: float) -> Assignment:
    """Optimal one-to-one assignment that only accepts pairs with ``cost < threshold``.

    Solves ``max sum over matched pairs of (threshold - cost)``: a pair is worth matching
    only when its cost is below the threshold, and the matching (not necessarily of maximum
    size) is optimal under that criterion. This is the same optimum as the JDE/UniTrack
    ``lap.lapjv(cost, extend_cost=True, cost_limit=threshold)`` call, where leaving a row or
    a column unmatched costs ``threshold / 2``; here it is solved with
    :func:`scipy.optimize.linear_sum_assignment` (Hungarian / Jonker-Volgenant).

    Args:
        cost: ``(n, m)`` cost matrix; ``inf`` entries are never matched.
        threshold: Pairs are accepted only when their cost is strictly below it.

    Returns:
        The :class:`Assignment`.

    Raises:
        ValueError: If ``cost`` is not 2-d or contains NaN.

    >>> a = linear_assignment(np.array([[0.1, 0.9], [0.2, 0.8]]), 0.5)
    >>> a.matches.tolist(), a.unmatched_rows.tolist(), a.unmatched_cols.tolist()
    ([[0, 0]], [1], [1])
    """
    c = np.asarray(cost, dtype=np.float64)
    if c.ndim != 2:
        raise ValueError(f"cost must be a 2-d (tracks x detections) matrix, got shape {c.shape}")
    if np.isnan(c).any():
        raise ValueError("cost contains NaN; check the similarity function and the boxes")
    n, m = c.shape
    if n == 0 or m == 0:
        return Assignment(
            np.empty((0, 2), dtype=np.int64), np.arange(n, dtype=np.int64),
            np.arange(m, dtype=np.int64),
        )
    feasible = c < threshold
    gain = np.where(feasible, threshold - np.where(feasible, c, 0.0), 0.0)
    rows, cols = linear_sum_assignment(gain, maximize=True)
    keep = feasible[rows, cols]
    rows, cols = rows[keep], cols[keep]
    matches = np.stack([rows, cols], axis=1).astype(np.int64)
    unmatched_rows = np.setdiff1d(np.arange(n), rows).astype(np.int64)
    unmatched_cols = np.setdiff1d(np.arange(m), cols).astype(np.int64)
    return Assignment(matches, unmatched_rows, unmatched_cols)


def iou_cost(boxes_a: np.ndarray, boxes_b: np.ndarray) -> np.ndarray:
    """Return the IoU distance ``1 - IoU`` between two sets of ``(x, y, w, h)`` boxes.

    Uses :func:`unitrack_env.geometry.box_iou` (TrackEval convention). Matching with
    ``linear_assignment(iou_cost(a, b), 1 - t)`` accepts pairs with ``IoU > t``.

    >>> iou_cost(np.array([[0, 0, 2, 2]]), np.array([[0, 0, 2, 2], [4, 4, 1, 1]]))
    array([[0., 1.]])
    """
    return 1.0 - box_iou(boxes_a, boxes_b)


def gate(
    cost: np.ndarray, motion_distance: np.ndarray, threshold: float = CHI2_95_4DOF
) -> np.ndarray:
    """Return a copy of ``cost`` with ``inf`` where ``motion_distance > threshold``.

    Args:
        cost: ``(n, m)`` cost matrix.
        motion_distance: ``(n, m)`` squared Mahalanobis distances.
        threshold: Gate; the chi-square 0.95 quantile for 4 dof by default (paper eq. gate).
    """
    c = np.array(cost, dtype=np.float64)
    c[np.asarray(motion_distance) > threshold] = np.inf
    return c


def fuse_motion(
    appearance_cost: np.ndarray,
    motion_distance: np.ndarray,
    appearance_weight: float = APPEARANCE_WEIGHT_PAPER,
    gate_threshold: float | None = CHI2_95_4DOF,
) -> np.ndarray:
    """Fuse appearance and motion costs (paper, Algorithm 1) and optionally gate.

    ``C = lambda * C_a + (1 - lambda) * C_m``, where ``C_m`` is the squared Mahalanobis
    distance. Gated pairs (``C_m > gate_threshold``) get ``inf`` *before* the assignment,
    as the authors' code does; the paper's Algorithm 1 instead filters gated pairs after
    the Hungarian step, which can let an impossible pair block a valid one.

    Args:
        appearance_cost: ``(n, m)`` appearance costs (e.g. ``1 - RSM``).
        motion_distance: ``(n, m)`` squared Mahalanobis distances.
        appearance_weight: ``lambda`` in ``[0, 1]``; paper 0.99, authors' code 0.98.
        gate_threshold: Gate on ``motion_distance``; ``None`` disables gating.

    Returns:
        ``(n, m)`` fused cost.
    """
    if not 0.0 <= appearance_weight <= 1.0:
        raise ValueError(f"appearance_weight must be in [0, 1], got {appearance_weight}")
    a = np.asarray(appearance_cost, dtype=np.float64)
    m = np.asarray(motion_distance, dtype=np.float64)
    if a.shape != m.shape:
        raise ValueError(
            f"appearance cost {a.shape} and motion distance {m.shape} must have the same shape"
        )
    fused = appearance_weight * a + (1.0 - appearance_weight) * m
    if gate_threshold is not None:
        fused = gate(fused, m, gate_threshold)
    return fused
