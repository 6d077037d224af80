"""Spaces shared by the environments, and helpers to build valid actions.

Why padded arrays plus a count instead of ``gymnasium.spaces.Sequence``: a frame holds a
variable number of detections and tracks; fixed-capacity arrays keep every observation a
plain dict of numpy arrays (cheap to copy, batch, pickle and check), and ``check_env``
accepts them. The capacity is a constructor argument of each environment.

The spaces live in one module per task family: :mod:`.arrays` (the variable-size
:class:`Image`, :class:`MaskStack` and :class:`LabelMap`), :mod:`.boxes` (MOT),
:mod:`.masks` (MOTS, VIS), :mod:`.poses` (PoseTrack), and :mod:`.limits` (the bounds and
checks they share). Import them from here.
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
