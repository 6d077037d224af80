"""Spaces shared by the environments, and helpers to build valid actions.

Padded arrays plus a count, not ``gymnasium.spaces.Sequence``: observations stay plain dicts
of numpy arrays (cheap to copy, batch, pickle and check) that ``check_env`` accepts. One
module per task family (:mod:`.arrays`, :mod:`.boxes`, :mod:`.masks`, :mod:`.poses`,
:mod:`.limits`); import them from here.
"""

from unitrack_env.spaces.arrays import Image, LabelMap, MaskStack
from unitrack_env.spaces.boxes import (
    box_array_space,
    detection_observation_space,
    pack_tracks,
    track_action_space,
    unpack_detections,
    unpack_tracks,
)
from unitrack_env.spaces.limits import COORD_MAX, FLOAT_MAX, ID_MAX
from unitrack_env.spaces.masks import (
    mask_boxes,
    mask_id_action_space,
    mask_observation_space,
    pack_mask_ids,
    unpack_mask_ids,
)
from unitrack_env.spaces.poses import (
    keypoint_array_space,
    pack_pose_tracks,
    pose_track_action_space,
    unpack_pose_tracks,
    unpack_poses,
)

__all__ = [
    "COORD_MAX",
    "FLOAT_MAX",
    "ID_MAX",
    "Image",
    "LabelMap",
    "MaskStack",
    "box_array_space",
    "detection_observation_space",
    "keypoint_array_space",
    "mask_boxes",
    "mask_id_action_space",
    "mask_observation_space",
    "pack_mask_ids",
    "pack_pose_tracks",
    "pack_tracks",
    "pose_track_action_space",
    "track_action_space",
    "unpack_detections",
    "unpack_mask_ids",
    "unpack_pose_tracks",
    "unpack_poses",
    "unpack_tracks",
]
