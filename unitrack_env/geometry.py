"""Box geometry shared by environments, metrics and agents.

Boxes are ``(n, 4)`` arrays of ``(x, y, w, h)``. Overlaps follow TrackEval's convention
(``x2 = x + w``, no ``+1``), so per-step rewards agree with the official scores.
"""

from __future__ import annotations

import numpy as np


def box_iou(boxes_a: np.ndarray, boxes_b: np.ndarray) -> np.ndarray:
    """Return the ``(n, m)`` float64 IoU matrix of two ``(x, y, w, h)`` box sets (empty union: 0).

    >>> box_iou(np.array([[0, 0, 2, 2]]), np.array([[1, 0, 2, 2], [5, 5, 1, 1]]))
    array([[0.33333333, 0.        ]])
    """
    a = np.asarray(boxes_a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(boxes_b, dtype=np.float64).reshape(-1, 4)
    if len(a) == 0 or len(b) == 0:
        return np.zeros((len(a), len(b)))
    ax2, ay2 = a[:, 0] + a[:, 2], a[:, 1] + a[:, 3]
    bx2, by2 = b[:, 0] + b[:, 2], b[:, 1] + b[:, 3]
    iw = np.minimum(ax2[:, None], bx2[None, :]) - np.maximum(a[:, None, 0], b[None, :, 0])
    ih = np.minimum(ay2[:, None], by2[None, :]) - np.maximum(a[:, None, 1], b[None, :, 1])
    inter = np.clip(iw, 0, None) * np.clip(ih, 0, None)
    # Areas as (x2 - x1) * (y2 - y1), TrackEval's arithmetic, so that ties round alike.
    area_a = np.clip(ax2 - a[:, 0], 0, None) * np.clip(ay2 - a[:, 1], 0, None)
    area_b = np.clip(bx2 - b[:, 0], 0, None) * np.clip(by2 - b[:, 1], 0, None)
    union = area_a[:, None] + area_b[None, :] - inter
    out = np.zeros_like(inter)
    np.divide(inter, union, out=out, where=union > 0)
    return out


def xywh_to_xyxy(boxes: np.ndarray) -> np.ndarray:
    """Convert ``(x, y, w, h)`` boxes to ``(x1, y1, x2, y2)``."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4).copy()
    b[:, 2:] += b[:, :2]
    return b
