"""Pose association spaces (PoseTrack): padded keypoint arrays and pose-track actions."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from unitrack_env.errors import InvalidActionError
from unitrack_env.spaces.limits import (
    COORD_MAX,
    checked_track_values,
    pad_tracks,
    refuse_duplicate_ids,
    track_arrays,
    valid_rows,
)


def keypoint_array_space(capacity: int, num_keypoints: int) -> spaces.Box:
    """``(capacity, num_keypoints, 3)`` float32 ``(x, y, score)`` poses; padding is 0.

    ``x, y`` are finite pixels (``|v| <= COORD_MAX``); ``score`` lies in ``[0, 1]``, where 0
    marks an absent keypoint.
    """
    low = np.tile(np.array([-COORD_MAX, -COORD_MAX, 0.0], np.float32), (capacity, num_keypoints, 1))
    high = np.tile(np.array([COORD_MAX, COORD_MAX, 1.0], np.float32), (capacity, num_keypoints, 1))
    return spaces.Box(low, high, (capacity, num_keypoints, 3), np.float32)


def pose_track_action_space(max_tracks: int, num_keypoints: int) -> spaces.Dict:
    """Action space of pose association tasks: padded ``ids``/``keypoints`` and ``num_tracks``."""
    return spaces.Dict(
        {
            # ids >= 1; 0 marks the padding past num_tracks
            "ids": spaces.Box(0, np.iinfo(np.int32).max, (max_tracks,), np.int64),
            "keypoints": keypoint_array_space(max_tracks, num_keypoints),
            "num_tracks": spaces.Discrete(max_tracks + 1),
        }
    )


def pack_pose_tracks(ids: Any, keypoints: Any, max_tracks: int) -> dict[str, Any]:
    """Build a padded pose-track action from ``k`` ids and ``(k, K, 3)`` keypoints.

    >>> action = pack_pose_tracks([4], np.ones((1, 17, 3)), max_tracks=3)
    >>> action["num_tracks"], action["ids"].tolist(), action["keypoints"].shape
    (1, [4, 0, 0], (3, 17, 3))
    """
    ids_arr = np.asarray(ids, dtype=np.int64).reshape(-1)
    kp = np.asarray(keypoints, dtype=np.float32)
    k = len(ids_arr)
    if kp.ndim != 3 or kp.shape[0] != k or kp.shape[2] != 3:
        raise InvalidActionError(f"{k} ids need keypoints of shape ({k}, K, 3); got {kp.shape}")
    return pad_tracks(ids_arr, kp, "keypoints", max_tracks)


def unpack_poses(observation: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Return the valid ``(keypoints (n, K, 3), scores (n,))`` of a pose observation."""
    return valid_rows(observation, "num_people", ("keypoints", "scores"))  # type: ignore[return-value]


def unpack_pose_tracks(
    action: dict[str, Any], max_tracks: int | None = None, num_keypoints: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Validate a pose-track action and return ``(ids (k,) int64, keypoints (k, K, 3) float64)``.

    Accepts the padded form (with ``num_tracks``) or the unpadded ``{"ids", "keypoints"}``;
    InvalidActionError names bad keys, shapes, dtypes, coordinates, scores or ids.
    """
    ids, kp = track_arrays(action, "keypoints", "pack_pose_tracks(ids, keypoints, max_tracks)")
    if kp.ndim != 3 or kp.shape[2] != 3 or (num_keypoints is not None
                                             and kp.shape[1] != num_keypoints):
        want = f"(k, {num_keypoints if num_keypoints is not None else 'K'}, 3)"
        raise InvalidActionError(f"action['keypoints'] must have shape {want}, got {kp.shape}")
    ids, kp = checked_track_values(action, ids, kp, "keypoints", "poses", max_tracks)
    k = len(ids)
    if not np.all(np.isfinite(kp)):
        row = int(np.argwhere(~np.isfinite(kp))[0, 0])
        raise InvalidActionError(f"track {ids[row]} has non-finite keypoints")
    if k and (kp[..., 2].min() < 0 or kp[..., 2].max() > 1):
        raise InvalidActionError("keypoint scores (the third value) must lie in [0, 1]")
    if k and np.abs(kp[..., :2]).max() > COORD_MAX:
        row = int(np.argwhere(np.abs(kp[..., :2]) > COORD_MAX)[0, 0])
        raise InvalidActionError(
            f"track {ids[row]} has a keypoint outside the action space: x and y must lie in "
            f"[-{COORD_MAX:g}, {COORD_MAX:g}] pixels")
    refuse_duplicate_ids(ids)
    return ids, kp

