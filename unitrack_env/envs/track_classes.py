"""The class of each track an agent answers with, from the detections it overlaps.

Box MOT agents answer with ids and boxes only; an environment that scores classes gives
each track a class by this rule (KITTI's): the KITTI and BDD100K envs (``classed_mot``) and
MOTChallenge-layout data with a class map.
"""

from __future__ import annotations

import numpy as np

from unitrack_env.geometry import box_iou


def track_classes(ids: np.ndarray, boxes: np.ndarray, det_boxes: np.ndarray,
                  det_classes: np.ndarray, last: dict[int, int], default: int) -> np.ndarray:
    """Each track's class: the class of the frame's detection it overlaps most (IoU > 0).

    A track that overlaps none keeps the class it had last (``last``, updated here: track
    id to class), else takes ``default``. Boxes are ``(x, y, w, h)``.
    """
    overlap = box_iou(np.asarray(boxes, np.float64).reshape(-1, 4), det_boxes) \
        if len(det_boxes) and len(ids) else np.zeros((len(ids), 0))
    out = np.empty(len(ids), dtype=np.int64)
    for k, track in enumerate(ids):
        if overlap.shape[1] and overlap[k].max() > 0:
            last[int(track)] = int(det_classes[int(overlap[k].argmax())])
        out[k] = last.setdefault(int(track), default)
    return out
