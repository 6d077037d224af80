"""Box association spaces (MOT): detection observations and padded track actions."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from unitrack_env.errors import InvalidActionError
from unitrack_env.spaces.arrays import Image
from unitrack_env.spaces.limits import (
    COORD_MAX,
    FLOAT_MAX,
    checked_track_values,
    pad_tracks,
    refuse_duplicate_ids,
    track_arrays,
    valid_rows,
)


def box_array_space(capacity: int) -> spaces.Box:
    """``(capacity, 4)`` float32 boxes ``(x, y, w, h)``: finite, ``w, h >= 0``; padding is 0."""
    low = np.tile(np.array([-COORD_MAX, -COORD_MAX, 0.0, 0.0], np.float32), (capacity, 1))
    return spaces.Box(low, np.float32(COORD_MAX), (capacity, 4), np.float32)


def detection_observation_space(
    max_detections: int, max_frame_size: tuple[int, int]
) -> spaces.Dict:
    """Observation space of box association tasks (see ``docs/architecture.md``)."""
    return spaces.Dict(
        {
            "frame": Image(*max_frame_size),
            "boxes": box_array_space(max_detections),
            "scores": spaces.Box(-FLOAT_MAX, FLOAT_MAX, (max_detections,), np.float32),
            "num_detections": spaces.Discrete(max_detections + 1),
        }
    )


def track_action_space(max_tracks: int) -> spaces.Dict:
    """Action space of box association tasks: padded ``ids``/``boxes`` and ``num_tracks``."""
    return spaces.Dict(
        {
            # ids >= 1; 0 marks the padding past num_tracks
            "ids": spaces.Box(0, np.iinfo(np.int32).max, (max_tracks,), np.int64),
            "boxes": box_array_space(max_tracks),
            "num_tracks": spaces.Discrete(max_tracks + 1),
        }
    )


def pack_tracks(ids: Any, boxes: Any, max_tracks: int) -> dict[str, Any]:
    """Build a padded track action from ``k`` ids and ``(k, 4)`` boxes.

    >>> action = pack_tracks([3, 7], [[0, 0, 10, 20], [5, 5, 10, 20]], max_tracks=4)
    >>> action["num_tracks"], action["ids"].tolist()
    (2, [3, 7, 0, 0])
    """
    ids_arr = np.asarray(ids, dtype=np.int64).reshape(-1)
    boxes_arr = np.asarray(boxes, dtype=np.float32).reshape(-1, 4)
    k = len(ids_arr)
    if len(boxes_arr) != k:
        raise InvalidActionError(f"{k} ids but {len(boxes_arr)} boxes")
    return pad_tracks(ids_arr, boxes_arr, "boxes", max_tracks)


def unpack_detections(observation: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Return the valid ``(boxes (n, 4), scores (n,))`` of a detection observation."""
    return valid_rows(observation, "num_detections", ("boxes", "scores"))  # type: ignore[return-value]


def unpack_tracks(
    action: dict[str, Any], max_tracks: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Validate a track action and return ``(ids (k,) int64, boxes (k, 4) float64)``.

    Accepts the padded form (with ``num_tracks``) or the unpadded ``{"ids", "boxes"}``;
    InvalidActionError names bad keys, shapes, dtypes, values or ids.
    """
    ids, boxes = track_arrays(action, "boxes", "pack_tracks(ids, boxes, max_tracks)")
    if boxes.ndim != 2 or boxes.shape[1] != 4:
        raise InvalidActionError(f"action['boxes'] must have shape (k, 4), got {boxes.shape}")
    ids, boxes = checked_track_values(action, ids, boxes, "boxes", "boxes", max_tracks)
    if not np.all(np.isfinite(boxes)):
        row = int(np.argwhere(~np.isfinite(boxes))[0, 0])
        raise InvalidActionError(f"track {ids[row]} has a non-finite box {boxes[row].tolist()}")
    negative = (boxes[:, 2] < 0) | (boxes[:, 3] < 0)
    if negative.any():
        row = int(np.argmax(negative))
        raise InvalidActionError(f"track {ids[row]} has a negative size {boxes[row].tolist()}")
    outside = np.abs(boxes) > COORD_MAX
    if outside.any():
        row = int(np.argwhere(outside)[0, 0])
        raise InvalidActionError(
            f"track {ids[row]} has a box {boxes[row].tolist()} outside the action space: box "
            f"values must lie in [-{COORD_MAX:g}, {COORD_MAX:g}] pixels")
    refuse_duplicate_ids(ids)
    return ids, boxes

