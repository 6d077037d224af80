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
    """Thresholded assignment: ``(k, 2)`` ``(row, column)`` matches, unmatched rows/columns."""

    matches: np.ndarray
    unmatched_rows: np.ndarray
    unmatched_cols: np.ndarray


def linear_assignment(cost: np.ndarray, threshold: float) -> Assignment:
    """Optimal one-to-one assignment that only accepts pairs with ``cost < threshold``.

    Maximises the sum of ``threshold - cost`` over matched pairs: the optimum of JDE/UniTrack's
    ``lap.lapjv(cost, extend_cost=True, cost_limit=threshold)``, solved with scipy's
    ``linear_sum_assignment``. ``inf`` entries are never matched; NaN raises ValueError.

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

    >>> iou_cost(np.array([[0, 0, 2, 2]]), np.array([[0, 0, 2, 2], [4, 4, 1, 1]]))
    array([[0., 1.]])
    """
    return 1.0 - box_iou(boxes_a, boxes_b)


def gate(
    cost: np.ndarray, motion_distance: np.ndarray, threshold: float = CHI2_95_4DOF
) -> np.ndarray:
    """Return a copy of ``cost`` with ``inf`` where ``motion_distance > threshold`` (eq. gate)."""
    c = np.array(cost, dtype=np.float64)
    c[np.asarray(motion_distance) > threshold] = np.inf
    return c


def fuse_motion(
    appearance_cost: np.ndarray,
    motion_distance: np.ndarray,
    appearance_weight: float = APPEARANCE_WEIGHT_PAPER,
    gate_threshold: float | None = CHI2_95_4DOF,
) -> np.ndarray:
    """Fuse appearance and motion costs (paper, Algorithm 1): ``lambda C_a + (1 - lambda) C_m``.

    Gated pairs (``C_m > gate_threshold``; ``None``: no gate) get ``inf`` *before* the
    assignment, as the authors' code does, so an impossible pair cannot block a valid one.
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
