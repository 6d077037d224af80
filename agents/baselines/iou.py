"""The IoU baseline: overlap + Hungarian matching with a track life cycle, no appearance.

It plays box association (MOT: box IoU with a constant-velocity guess), mask association
(MOTS, VIS: mask IoU with the track's last mask, via ``pycocotools``) and pose association
(PoseTrack: object keypoint similarity, OKS, with the track's last pose) with the same life
cycle; the observation decides (``"masks"`` in it means mask association, ``"keypoints"``
pose association).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from unitrack_env.agents.base import Agent
from unitrack_env.geometry import box_iou
from unitrack_env.spaces import (
    pack_mask_ids,
    pack_pose_tracks,
    pack_tracks,
    unpack_detections,
    unpack_poses,
)

OKS_SIGMAS: np.ndarray = np.array([
    0.026, 0.025, 0.025, 0.035, 0.035, 0.079, 0.079, 0.072, 0.072, 0.062, 0.062,
    0.107, 0.107, 0.087, 0.087, 0.089, 0.089,
])
"""Per-keypoint OKS falloff ``sigma`` of the 17 PoseTrack keypoints: COCO's values by position
(COCO keypoint evaluation). PoseTrack's second and third keypoints (head bottom, head top)
sit where COCO has the eyes and take their 0.025."""

DEFAULT_MAX_TRACKS: int = 512
"""Default action capacity of box tracks (the MOTChallenge environments' ``max_tracks``)."""

POSE_MAX_TRACKS: int = 100
"""Default action capacity of pose tracks (the PoseTrack environment's ``max_tracks``)."""


def object_keypoint_similarity(
    poses_a: np.ndarray, poses_b: np.ndarray, sigmas: np.ndarray = OKS_SIGMAS
) -> np.ndarray:
    """OKS between every pose of ``poses_a`` and every pose of ``poses_b``.

    ``OKS(a, b) = mean over keypoints visible in both of exp(-d^2 / (2 s^2 (2 sigma)^2))``,
    the COCO keypoint similarity with ``s^2`` the area of ``a``'s visible-keypoint box (COCO
    uses the annotated segment's area, which poses do not have) and ``d`` the keypoint
    distance. Pairs with no keypoint visible in both have OKS 0.

    Args:
        poses_a: ``(n, K, 3)`` ``(x, y, score)``; a keypoint is visible when its score is > 0.
        poses_b: ``(m, K, 3)``.
        sigmas: ``(K,)`` per-keypoint falloff.

    Returns:
        ``(n, m)`` similarities in ``[0, 1]``.

    >>> a = np.zeros((1, 17, 3)); a[0, :, 2] = 1; a[0, :, 0] = np.arange(17) * 10
    >>> a[0, :, 1] = np.arange(17) * 20
    >>> float(object_keypoint_similarity(a, a)[0, 0])
    1.0
    """
    a = np.asarray(poses_a, dtype=np.float64)
    b = np.asarray(poses_b, dtype=np.float64)
    if not len(a) or not len(b):
        return np.zeros((len(a), len(b)))
    vis_a = a[:, :, 2] > 0
    vis_b = b[:, :, 2] > 0
    area = np.zeros(len(a))
    for i in range(len(a)):
        pts = a[i, vis_a[i], :2]
        if len(pts):
            w, h = pts.max(axis=0) - pts.min(axis=0)
            area[i] = w * h
    area = np.maximum(area, 1.0)  # a single visible keypoint: a 1-pixel object
    d2 = ((a[:, None, :, :2] - b[None, :, :, :2]) ** 2).sum(-1)  # (n, m, K)
    kappa2 = (2.0 * np.asarray(sigmas, dtype=np.float64)) ** 2
    sim = np.exp(-d2 / (2.0 * area[:, None, None] * kappa2[None, None, :]))
    both = vis_a[:, None, :] & vis_b[None, :, :]
    count = both.sum(-1)
    return np.where(count > 0, (sim * both).sum(-1) / np.maximum(count, 1), 0.0)


@dataclass(frozen=True)
class IoUConfig:
    """Parameters of the IoU baseline.

    Attributes:
        iou_threshold: least IoU between a track's predicted box and a detection to match.
        min_score: detections scored below this are ignored (scores are benchmark-specific:
            MOT17 FRCNN scores lie in [0, 1], MOT15's are unbounded).
        min_hits: a track is reported once it has been matched this many times (during the
            first ``min_hits`` frames of an episode every matched track is reported, so the
            opening frames are not lost).
        max_lost_seconds: a track that found no detection is kept this long (converted to
            frames with the sequence's frame rate) before it is dropped.
        velocity_smoothing: weight of the newest displacement in the exponentially smoothed
            velocity that predicts where a track is in the next frame (0 = no motion model).
        duplicate_iou: an unmatched detection that overlaps a matched one by at least this
            IoU is treated as a duplicate detection and starts no track (1 = off).
        oks_threshold: poses: least OKS between a track's last pose and a detection to match
            (:func:`object_keypoint_similarity`; used instead of ``iou_threshold``). On the
            synthetic PoseTrack set IDF1 is 0.80 / 0.90 at 0.1-0.2, 0.78 / 0.89 at 0.3,
            0.77 / 0.80 at 0.5 and 0.65 / 0.76 at 0.7 (fast motion lowers the OKS of a
            person with itself one frame later).
        duplicate_oks: poses: an unmatched pose with at least this OKS to a matched one is a
            duplicate and starts no track (1 = off).
    """

    iou_threshold: float = 0.3
    min_score: float = -np.inf
    min_hits: int = 2
    max_lost_seconds: float = 1.0
    velocity_smoothing: float = 0.5
    duplicate_iou: float = 0.3
    oks_threshold: float = 0.2
    duplicate_oks: float = 0.8


class IoUAgent(Agent, name="iou", tasks=("mot", "mots", "vis", "posetrack")):
    """Associates detections to tracks by IoU with a constant-velocity guess.

    Per frame: predict each track's box (last box + smoothed velocity, times the frames it
    has been lost), match predictions to detections with the Hungarian algorithm on IoU,
    start a track for every unmatched detection, and drop tracks lost longer than
    ``max_lost_seconds``. Only tracks matched in this frame are reported.

    On mask observations (``masks``, ``scores``, ``num_detections``) the overlap is mask IoU
    between each track's last mask and the detections (no motion model; masks of one step
    apart overlap), and the action gives each detection its track id (0 = not reported).

    On pose observations (``keypoints``, ``scores``, ``num_people``) the overlap is the
    object keypoint similarity (OKS) between each track's last pose and the detections,
    thresholded at ``oks_threshold``; the action echoes the matched poses with their ids.

    Args:
        max_tracks: action capacity of box and pose tracks (must match the environment's
            ``max_tracks``); None: 512 for boxes, 100 for poses (the environments' defaults).
        **config: fields of :class:`IoUConfig`.
    """

    config_class = IoUConfig

    def __init__(self, max_tracks: int | None = None, **config: Any) -> None:
        self.config = IoUConfig(**config)
        self._max_tracks = max_tracks
        self._reset_state(30.0)

    @property
    def max_tracks(self) -> int:
        """Action capacity of box tracks (the default when not given)."""
        return DEFAULT_MAX_TRACKS if self._max_tracks is None else int(self._max_tracks)

    def _reset_state(self, frame_rate: float) -> None:
        self._max_lost = max(1, round(self.config.max_lost_seconds * frame_rate))
        self._next_id = 1
        self._frame = 0
        self._ids = np.zeros(0, dtype=np.int64)
        self._boxes = np.zeros((0, 4))
        self._velocity = np.zeros((0, 4))
        self._hits = np.zeros(0, dtype=np.int64)
        self._lost = np.zeros(0, dtype=np.int64)
        self._rles: list[dict] = []
        self._poses = np.zeros((0, 0, 3))

    def reset(self, observation: Any, info: dict[str, Any]) -> None:
        """Forget all tracks; read the frame rate for the lost-track age."""
        self._reset_state(float(info.get("frame_rate", 30.0)))

    def act(self, observation: dict[str, Any]) -> dict[str, Any]:
        """Match this frame's detections to the tracks and report the matched tracks."""
        if "masks" in observation:
            return self._act_masks(observation)
        if "keypoints" in observation:
            return self._act_poses(observation)
        cfg = self.config
        self._frame += 1
        boxes, scores = unpack_detections(observation)
        boxes = boxes[scores >= cfg.min_score].astype(np.float64)

        predicted = self._boxes + self._velocity * (self._lost + 1)[:, None]
        matched_tracks = np.zeros(len(self._ids), dtype=bool)
        matched_dets = np.zeros(len(boxes), dtype=bool)
        if len(predicted) and len(boxes):
            iou = box_iou(predicted, boxes)
            rows, cols = linear_sum_assignment(-iou)
            ok = iou[rows, cols] >= cfg.iou_threshold
            rows, cols = rows[ok], cols[ok]
            displacement = (boxes[cols] - self._boxes[rows]) / (self._lost[rows] + 1)[:, None]
            a = cfg.velocity_smoothing
            first = self._hits[rows] == 1
            self._velocity[rows] = np.where(
                first[:, None], displacement, a * displacement + (1 - a) * self._velocity[rows]
            )
            self._boxes[rows] = boxes[cols]
            self._hits[rows] += 1
            self._lost[rows] = 0
            matched_tracks[rows] = True
            matched_dets[cols] = True
        self._lost[~matched_tracks] += 1

        new = boxes[~matched_dets]
        if len(new) and matched_dets.any() and cfg.duplicate_iou < 1.0:
            # A detection overlapping an already matched one is a duplicate, not a new object.
            overlap = box_iou(new, boxes[matched_dets]).max(axis=1)
            new = new[overlap < cfg.duplicate_iou]
        new_ids = np.arange(self._next_id, self._next_id + len(new))
        self._next_id += len(new)
        keep = self._lost <= self._max_lost
        self._ids = np.concatenate([self._ids[keep], new_ids])
        self._boxes = np.concatenate([self._boxes[keep], new])
        self._velocity = np.concatenate([self._velocity[keep], np.zeros((len(new), 4))])
        self._hits = np.concatenate([self._hits[keep], np.ones(len(new), dtype=np.int64)])
        self._lost = np.concatenate([self._lost[keep], np.zeros(len(new), dtype=np.int64)])

        active = self._lost == 0
        if self._frame > cfg.min_hits:
            active &= self._hits >= cfg.min_hits
        return pack_tracks(self._ids[active], self._boxes[active], self.max_tracks)

    def _act_masks(self, observation: dict[str, Any]) -> dict[str, Any]:
        """Mask association: match by mask IoU, give each detection its track id."""
        from pycocotools import mask as mask_utils

        cfg = self.config
        self._frame += 1
        n = int(observation["num_detections"])
        capacity = len(observation["scores"])
        masks = np.asarray(observation["masks"][:n], dtype=bool)
        valid = np.flatnonzero(np.asarray(observation["scores"][:n]) >= cfg.min_score)
        rles = mask_utils.encode(np.asfortranarray(masks[valid].transpose(1, 2, 0).astype(np.uint8))
                                 ) if len(valid) else []
        det_track = np.full(len(valid), -1, dtype=np.int64)  # track row of each detection
        matched_tracks = np.zeros(len(self._ids), dtype=bool)
        if len(self._ids) and len(valid):
            iou = np.asarray(mask_utils.iou(self._rles, rles, [False] * len(rles))
                             ).reshape(len(self._ids), len(valid))
            rows, cols = linear_sum_assignment(-iou)
            ok = iou[rows, cols] >= cfg.iou_threshold
            rows, cols = rows[ok], cols[ok]
            for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
                self._rles[r] = rles[c]
            self._hits[rows] += 1
            self._lost[rows] = 0
            matched_tracks[rows] = True
            det_track[cols] = rows
        self._lost[~matched_tracks] += 1

        new = np.flatnonzero(det_track < 0)
        matched = np.flatnonzero(det_track >= 0)
        if len(new) and len(matched) and cfg.duplicate_iou < 1.0:
            overlap = np.asarray(mask_utils.iou([rles[i] for i in new], [rles[i] for i in matched],
                                                [False] * len(matched))
                                 ).reshape(len(new), len(matched)).max(axis=1)
            new = new[overlap < cfg.duplicate_iou]
        keep = self._lost <= self._max_lost
        kept_rows = np.flatnonzero(keep)
        remap = np.full(len(self._ids), -1, dtype=np.int64)
        remap[kept_rows] = np.arange(len(kept_rows))
        det_track[matched] = remap[det_track[matched]]
        det_track[new] = len(kept_rows) + np.arange(len(new))
        new_ids = np.arange(self._next_id, self._next_id + len(new))
        self._next_id += len(new)
        self._ids = np.concatenate([self._ids[keep], new_ids])
        self._rles = [self._rles[r] for r in kept_rows] + [rles[i] for i in new]
        self._hits = np.concatenate([self._hits[keep], np.ones(len(new), dtype=np.int64)])
        self._lost = np.concatenate([self._lost[keep], np.zeros(len(new), dtype=np.int64)])

        ids = np.zeros(n, dtype=np.int64)
        for j in np.flatnonzero(det_track >= 0):
            row = det_track[j]
            if self._frame <= cfg.min_hits or self._hits[row] >= cfg.min_hits:
                ids[valid[j]] = self._ids[row]
        return pack_mask_ids(ids, capacity)

    def _act_poses(self, observation: dict[str, Any]) -> dict[str, Any]:
        """Pose association: match by OKS with each track's last pose, echo matched poses."""
        cfg = self.config
        self._frame += 1
        keypoints, scores = unpack_poses(observation)
        keypoints = np.asarray(keypoints, dtype=np.float32)
        valid = np.flatnonzero((np.asarray(scores) >= cfg.min_score)
                               & (keypoints[:, :, 2] > 0).any(axis=1))
        poses = keypoints[valid]
        if not len(self._poses):
            self._poses = np.zeros((0,) + keypoints.shape[1:], dtype=np.float32)
        det_track = np.full(len(valid), -1, dtype=np.int64)
        matched_tracks = np.zeros(len(self._ids), dtype=bool)
        if len(self._ids) and len(valid):
            oks = object_keypoint_similarity(self._poses, poses)
            rows, cols = linear_sum_assignment(-oks)
            ok = oks[rows, cols] >= cfg.oks_threshold
            rows, cols = rows[ok], cols[ok]
            self._poses[rows] = poses[cols]
            self._hits[rows] += 1
            self._lost[rows] = 0
            matched_tracks[rows] = True
            det_track[cols] = rows
        self._lost[~matched_tracks] += 1

        new = np.flatnonzero(det_track < 0)
        matched = np.flatnonzero(det_track >= 0)
        if len(new) and len(matched) and cfg.duplicate_oks < 1.0:
            overlap = object_keypoint_similarity(poses[new], poses[matched]).max(axis=1)
            new = new[overlap < cfg.duplicate_oks]
        keep = self._lost <= self._max_lost
        kept_rows = np.flatnonzero(keep)
        remap = np.full(len(self._ids), -1, dtype=np.int64)
        remap[kept_rows] = np.arange(len(kept_rows))
        det_track[matched] = remap[det_track[matched]]
        new_ids = np.arange(self._next_id, self._next_id + len(new))
        self._next_id += len(new)
        self._ids = np.concatenate([self._ids[keep], new_ids])
        self._poses = np.concatenate([self._poses[keep], poses[new]])
        self._hits = np.concatenate([self._hits[keep], np.ones(len(new), dtype=np.int64)])
        self._lost = np.concatenate([self._lost[keep], np.zeros(len(new), dtype=np.int64)])
        det_track[new] = len(kept_rows) + np.arange(len(new))

        out_ids, out_poses = [], []
        for j in np.flatnonzero(det_track >= 0):
            row = det_track[j]
            if self._frame <= cfg.min_hits or self._hits[row] >= cfg.min_hits:
                out_ids.append(self._ids[row])
                out_poses.append(poses[j])
        capacity = POSE_MAX_TRACKS if self._max_tracks is None else int(self._max_tracks)
        return pack_pose_tracks(out_ids, np.array(out_poses, dtype=np.float32).reshape(
            len(out_ids), *keypoints.shape[1:]), capacity)
