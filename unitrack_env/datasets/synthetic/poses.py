"""Keypoints of the synthetic people: one walking stick figure, two benchmark joint sets.

A person of the scene engine is drawn as a silhouette inside its placement box;
:data:`SKELETON_JOINTS` sit inside it in the box's normalised ``(u, v)`` coordinates, so the
joints move exactly with the textured sprite. The person faces the camera (its right side on
the image left, as JHMDB and PoseTrack annotate frontal people); walking swings the legs and,
in anti-phase, the arms with a phase that advances with the distance walked. Both
benchmarks' joint sets are read off this one skeleton, and :func:`joint_visibility` judges
each joint on the rendered instance map (a wrist beside the body lands on background and
stays visible). Coordinates are 0-based pixel centres, like the scene engine's boxes.
"""

from __future__ import annotations

from types import MappingProxyType

import numpy as np

from unitrack_env.datasets.synthetic.scene_model import ObjectRole, SceneObject
from unitrack_env.datasets.synthetic.sprites import HEAD_RADIUS

SKELETON_JOINTS: tuple[str, ...] = (
    "head_top",
    "nose",
    "neck",
    "belly",
    "right_shoulder",
    "left_shoulder",
    "right_elbow",
    "left_elbow",
    "right_wrist",
    "left_wrist",
    "right_hip",
    "left_hip",
    "right_knee",
    "left_knee",
    "right_ankle",
    "left_ankle",
)
"""Joints of the underlying skeleton (16)."""

#: Rest pose ``(u, v)`` of every skeleton joint inside the person's box (normalised).
REST_POSE: MappingProxyType[str, tuple[float, float]] = MappingProxyType({
    "head_top": (0.5, 0.015),
    "nose": (0.5, HEAD_RADIUS),
    "neck": (0.5, 0.2),
    "belly": (0.5, 0.45),
    "right_shoulder": (0.26, 0.25),
    "left_shoulder": (0.74, 0.25),
    "right_elbow": (0.17, 0.41),
    "left_elbow": (0.83, 0.41),
    "right_wrist": (0.16, 0.57),
    "left_wrist": (0.84, 0.57),
    "right_hip": (0.37, 0.58),
    "left_hip": (0.63, 0.58),
    "right_knee": (0.36, 0.78),
    "left_knee": (0.64, 0.78),
    "right_ankle": (0.37, 0.97),
    "left_ankle": (0.63, 0.97),
})

#: Horizontal swing amplitude (fraction of the box width) of each swinging joint, and the
#: sign of its phase: legs of one side swing against the arm of the same side.
SWING: MappingProxyType[str, tuple[float, float]] = MappingProxyType({
    "right_elbow": (0.06, -1.0),
    "left_elbow": (0.06, 1.0),
    "right_wrist": (0.13, -1.0),
    "left_wrist": (0.13, 1.0),
    "right_knee": (0.08, 1.0),
    "left_knee": (0.08, -1.0),
    "right_ankle": (0.16, 1.0),
    "left_ankle": (0.16, -1.0),
})

#: Vertical lift (fraction of the box height) of a knee / ankle at the top of its swing.
LEG_LIFT: float = 0.025
#: Distance walked per gait cycle, in person heights.
STRIDE_HEIGHTS: float = 0.9
#: Below this speed (pixels per frame) a person counts as standing (no swing).
STANDING_SPEED: float = 0.05

JHMDB_FROM_SKELETON: tuple[str, ...] = (
    "neck", "belly", "nose", "right_shoulder", "left_shoulder", "right_hip", "left_hip",
    "right_elbow", "left_elbow", "right_knee", "left_knee", "right_wrist", "left_wrist",
    "right_ankle", "left_ankle",
)
"""Skeleton joint of each JHMDB joint, in ``pos_img`` order (JHMDB's ``face`` is the head
centre, here called ``nose``)."""

POSETRACK_FROM_SKELETON: tuple[str | None, ...] = (
    "nose", "neck", "head_top", None, None,
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist",
    "right_wrist", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle",
    "right_ankle",
)
"""Skeleton joint of each PoseTrack 2018 keypoint (COCO order: nose, head_bottom,
head_top, left_ear, right_ear, shoulders, elbows, wrists, hips, knees, ankles); None for
the ear slots PoseTrack leaves unannotated."""


def gait_phase(obj: SceneObject, t: float) -> float:
    """Return the gait phase (radians) of ``obj`` at frame ``t``.

    The phase grows with the horizontal distance walked since the trajectory's anchor, so
    a faster walker swings faster; it is 0 for a person that does not walk.
    """
    vx = obj.trajectory.velocity[0]
    if obj.role is not ObjectRole.PEDESTRIAN or abs(vx) < STANDING_SPEED:
        return 0.0
    height = obj.base_size[1] * obj.trajectory.scale(t)
    walked = abs(vx) * (t - obj.trajectory.anchor_frame)
    return float(2.0 * np.pi * walked / (STRIDE_HEIGHTS * max(height, 1.0)))


def skeleton_uv(obj: SceneObject, t: float) -> np.ndarray:
    """Return the ``(16, 2)`` normalised ``(u, v)`` skeleton of ``obj`` at frame ``t``."""
    phase = gait_phase(obj, t)
    direction = 1.0 if obj.trajectory.velocity[0] >= 0 else -1.0
    walking = obj.role is ObjectRole.PEDESTRIAN and abs(
        obj.trajectory.velocity[0]) >= STANDING_SPEED
    uv = np.array([REST_POSE[name] for name in SKELETON_JOINTS], dtype=np.float64)
    if walking:
        for i, name in enumerate(SKELETON_JOINTS):
            if name in SWING:
                amplitude, sign = SWING[name]
                swing = sign * np.sin(phase)
                uv[i, 0] += direction * amplitude * swing
                if name.endswith(("knee", "ankle")):
                    uv[i, 1] -= LEG_LIFT * max(swing, 0.0)
        uv[SKELETON_JOINTS.index("nose"), 0] += direction * 0.04  # head turned to the path
    return uv


def skeleton_pixels(obj: SceneObject, t: int) -> np.ndarray:
    """Return the ``(16, 2)`` skeleton of ``obj`` at frame ``t`` in 0-based image pixels.

    Uses the same integer placement as the renderer (:meth:`SceneObject.box_at`): pixel
    column ``x`` of the sprite has ``u = (x - x0 + 0.5) / w``, so ``x = x0 + u * w - 0.5``.
    """
    x0, y0, w, h = obj.box_at(t)
    uv = skeleton_uv(obj, t)
    return np.stack([x0 + uv[:, 0] * w - 0.5, y0 + uv[:, 1] * h - 0.5], axis=1)


def head_box(obj: SceneObject, t: int) -> tuple[float, float, float, float]:
    """Return the ``(x, y, w, h)`` box around the head disc (PoseTrack's ``bbox_head``)."""
    x0, y0, w, h = obj.box_at(t)
    radius = HEAD_RADIUS * h
    return (x0 + 0.5 * w - radius, float(y0), 2.0 * radius, 2.0 * radius)


def select_joints(skeleton: np.ndarray, names: tuple[str | None, ...]) -> np.ndarray:
    """Return ``(len(names), 2)`` joints picked from a ``(16, 2)`` skeleton (NaN for None)."""
    out = np.full((len(names), 2), np.nan)
    for i, name in enumerate(names):
        if name is not None:
            out[i] = skeleton[SKELETON_JOINTS.index(name)]
    return out


def joint_visibility(
    joints: np.ndarray, instance_map: np.ndarray, object_id: int
) -> tuple[np.ndarray, np.ndarray]:
    """``(inside, visible)`` ``(J,)`` masks: joints in the image, and not occluded by others."""
    height, width = instance_map.shape
    finite = np.all(np.isfinite(joints), axis=1)
    cols = np.where(finite, np.round(np.nan_to_num(joints[:, 0])), -1).astype(np.int64)
    rows = np.where(finite, np.round(np.nan_to_num(joints[:, 1])), -1).astype(np.int64)
    inside = finite & (cols >= 0) & (cols < width) & (rows >= 0) & (rows < height)
    owner = np.zeros(len(joints), dtype=np.int64)
    owner[inside] = instance_map[rows[inside], cols[inside]]
    visible = inside & ((owner == 0) | (owner == object_id))
    return inside, visible
