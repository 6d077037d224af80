"""poseval's joints and frames: which keypoints are scored, and one frame's persons.

A :class:`PoseFrame` holds one frame's persons as poseval sees them (15 joints, head sizes,
track ids); :func:`joint_distances` gives the head-normalised distances the matching uses.
Definitions in :mod:`unitrack_env.metrics.posetrack`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from types import MappingProxyType

import cv2
import numpy as np

from unitrack_env.datasets.posetrack_records import POSETRACK_KEYPOINTS, PoseTrackPerson

POSEVAL_JOINTS: tuple[str, ...] = (
    "right_ankle", "right_knee", "right_hip", "left_hip", "left_knee", "left_ankle",
    "right_wrist", "right_elbow", "right_shoulder", "left_shoulder", "left_elbow",
    "left_wrist", "head_bottom", "nose", "head_top",
)
"""poseval's 15 joints in its ``Joint`` order (``head_bottom`` is poseval's ``neck``)."""

NUM_JOINTS: int = len(POSEVAL_JOINTS)

#: Column of each poseval joint in the 17 PoseTrack keypoints.
KEYPOINT_OF_JOINT: tuple[int, ...] = tuple(POSETRACK_KEYPOINTS.index(n) for n in POSEVAL_JOINTS)

#: poseval's body-part columns (``getCum``): joints averaged into each printed column.
BODY_PARTS: MappingProxyType[str, tuple[str, ...]] = MappingProxyType({
    "Head": ("head_top", "head_bottom", "nose"),
    "Shou": ("right_shoulder", "left_shoulder"),
    "Elb": ("right_elbow", "left_elbow"),
    "Wri": ("right_wrist", "left_wrist"),
    "Hip": ("right_hip", "left_hip"),
    "Knee": ("right_knee", "left_knee"),
    "Ankl": ("right_ankle", "left_ankle"),
})

#: Match threshold on the head-normalised distance (poseval's ``distThresh``).
DIST_THRESHOLD: float = 0.5
#: Head size = this factor x the diagonal of the head box (poseval's ``getHeadSize``).
HEAD_SIZE_FACTOR: float = 0.6
#: poseval leaves out the last evaluated frame of every sequence (``imgidxs[:-1]``).
POSEVAL_DROPS_LAST_FRAME: bool = True
#: Ids of poseval's dummy miss / false positive in frames without GT or predictions.
DUMMY_GT_ID: int = -(2**62)
DUMMY_PRED_ID: int = -(2**62)


# --------------------------------------------------------------------------- frames
@dataclass(frozen=True)
class PoseFrame:
    """The persons of one frame, reduced to poseval's 15 joints (``head_size``: NaN if unknown)."""

    ids: np.ndarray
    xy: np.ndarray
    present: np.ndarray
    head_size: np.ndarray

    def __len__(self) -> int:
        return len(self.ids)

    @classmethod
    def empty(cls) -> PoseFrame:
        """A frame without persons."""
        return cls(np.zeros(0, np.int64), np.zeros((0, NUM_JOINTS, 2)),
                   np.zeros((0, NUM_JOINTS), bool), np.zeros(0))

    @classmethod
    def from_keypoints(
        cls,
        ids: Sequence[int] | np.ndarray,
        keypoints: np.ndarray,
        bbox_head: np.ndarray | None = None,
    ) -> PoseFrame:
        """Build a frame from ``(n, 17, 3)`` ``(x, y, v)`` keypoints (``(0, 0, 0)``: absent)."""
        kp = np.asarray(keypoints, dtype=np.float64).reshape(-1, len(POSETRACK_KEYPOINTS), 3)
        ids_arr = np.asarray(ids, dtype=np.int64).reshape(-1)
        if len(ids_arr) != len(kp):
            raise ValueError(f"{len(ids_arr)} ids but {len(kp)} poses")
        cols = list(KEYPOINT_OF_JOINT)
        xy = kp[:, cols, :2].copy()
        present = ~np.all(kp[:, cols, :] == 0.0, axis=2)
        return cls(ids_arr, xy, present, head_sizes(bbox_head, len(kp)))

    @classmethod
    def from_people(cls, people: Sequence[PoseTrackPerson], *, dummy_id: int = -1) -> PoseFrame:
        """Build a frame from parsed persons (missing track ids become ``dummy_id``)."""
        if not people:
            return cls.empty()
        ids = [p.track_id if p.track_id is not None else dummy_id for p in people]
        keypoints = np.stack([p.keypoints for p in people])
        heads = np.array([p.bbox_head if p.bbox_head is not None else (np.nan,) * 4
                          for p in people], dtype=np.float64)
        return cls.from_keypoints(ids, keypoints, heads)



def head_sizes(bbox_head: np.ndarray | None, count: int) -> np.ndarray:
    """Return ``0.6 x`` the head-box diagonal of each person (NaN without a head box)."""
    if bbox_head is None:
        return np.full(count, np.nan)
    boxes = np.asarray(bbox_head, dtype=np.float64).reshape(-1, 4)
    return HEAD_SIZE_FACTOR * np.hypot(boxes[:, 2], boxes[:, 3])


def remove_ignored(frame: PoseFrame, regions: Sequence[np.ndarray]) -> PoseFrame:
    """Drop joints strictly inside any ignore polygon, then persons left without joints.

    Mirrors poseval's ``removeIgnoredPointsRects``, which runs only on frames that have
    ignore regions: a person with no joint left (or none to begin with) is removed.
    Polygons with fewer than 3 vertices contain nothing.
    """
    if not regions:
        return frame
    polygons = [np.asarray(p, np.float32).reshape(-1, 2) for p in regions]
    polygons = [p for p in polygons if len(p) >= 3]
    present = frame.present.copy()
    for poly in polygons:
        contour = poly.reshape(-1, 1, 2)
        for n, j in zip(*np.nonzero(present), strict=True):
            x, y = frame.xy[n, j]
            if cv2.pointPolygonTest(contour, (float(x), float(y)), False) > 0:
                present[n, j] = False
    keep = present.any(axis=1)
    return PoseFrame(frame.ids[keep], frame.xy[keep], present[keep], frame.head_size[keep])


def joint_distances(gt: PoseFrame, pred: PoseFrame) -> np.ndarray:
    """Return ``(len(gt), len(pred), 15)`` head-normalised joint distances.

    Entries are ``inf`` where the joint is missing on either side.
    """
    diff = gt.xy[:, None] - pred.xy[None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        dist = np.hypot(diff[..., 0], diff[..., 1]) / gt.head_size[:, None, None]
    both = gt.present[:, None, :] & pred.present[None, :, :]
    return np.where(both, dist, np.inf)

