"""Overlap measures for appearance-free tracking: box IoU, mask IoU and pose OKS.

A measure tells an :class:`~unitrack_env.agents.primitives.overlap_tracker.OverlapTracker`
a detection's state, how similar two sets of states are, and how a track follows its
matches: :class:`BoxOverlap` (IoU with a constant-velocity guess), :class:`MaskOverlap`
(RLE mask IoU, no motion) and :class:`PoseOverlap` (OKS).
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Generic, TypeVar

import numpy as np

from unitrack_env.geometry import box_iou

if TYPE_CHECKING:
    from .overlap_tracker import OverlapTrack

S = TypeVar("S")
"""Type of a detection's (and a track's) state under one measure."""

OKS_SIGMAS: np.ndarray = np.array([
    0.026, 0.025, 0.025, 0.035, 0.035, 0.079, 0.079, 0.072, 0.072, 0.062, 0.062,
    0.107, 0.107, 0.087, 0.087, 0.089, 0.089,
])
"""Per-keypoint OKS falloff ``sigma`` of the 17 PoseTrack keypoints: COCO's values by position
(COCO keypoint evaluation). PoseTrack's second and third keypoints (head bottom, head top)
sit where COCO has the eyes and take their 0.025."""


def object_keypoint_similarity(
    poses_a: np.ndarray, poses_b: np.ndarray, sigmas: np.ndarray = OKS_SIGMAS
) -> np.ndarray:
    """OKS ``(n, m)`` between every pose of ``poses_a`` and every pose of ``poses_b``.

    COCO's keypoint similarity over keypoints visible (score > 0) in both, with ``s^2`` the
    area of ``a``'s visible-keypoint box (poses have no segment area); 0 when none is shared.

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


class OverlapMeasure(abc.ABC, Generic[S]):
    """How an overlap tracker compares detections with tracks (no appearance)."""

    @abc.abstractmethod
    def states(self, detections: Any) -> list[S]:
        """One state per detection of a frame (e.g. the rows of a box array)."""

    @abc.abstractmethod
    def similarity(self, a: Sequence[S], b: Sequence[S]) -> np.ndarray:
        """``(len(a), len(b))`` overlap of two non-empty state lists."""

    def predict(self, track: OverlapTrack[S]) -> S:
        """Where ``track`` is expected now (default: its last state)."""
        return track.state

    def update(self, track: OverlapTrack[S], state: S) -> None:
        """Follow a match (called before the track's hit and lost counts change)."""
        track.state = state


class BoxOverlap(OverlapMeasure[np.ndarray]):
    """Box IoU with a constant-velocity guess (``velocity_smoothing``: newest step weight)."""

    def __init__(self, velocity_smoothing: float = 0.5) -> None:
        self.velocity_smoothing = velocity_smoothing

    def states(self, detections: Any) -> list[np.ndarray]:
        """The rows of an ``(m, 4)`` ``(x, y, w, h)`` box array, as float64."""
        return list(np.asarray(detections, dtype=np.float64).reshape(-1, 4))

    def similarity(self, a: Sequence[np.ndarray], b: Sequence[np.ndarray]) -> np.ndarray:
        """Box IoU."""
        return box_iou(np.stack(a), np.stack(b))

    def predict(self, track: OverlapTrack[np.ndarray]) -> np.ndarray:
        """Last box plus the velocity times the frames since the last match (and this one)."""
        return track.state + self._velocity(track) * (track.lost + 1)

    def update(self, track: OverlapTrack[np.ndarray], state: np.ndarray) -> None:
        """Smooth the velocity with the displacement per frame, then take the new box."""
        displacement = (state - track.state) / (track.lost + 1)
        a = self.velocity_smoothing
        track.velocity = displacement if track.hits == 1 \
            else a * displacement + (1 - a) * self._velocity(track)
        track.state = state

    @staticmethod
    def _velocity(track: OverlapTrack[np.ndarray]) -> np.ndarray:
        return track.velocity if track.velocity is not None else np.zeros(4)


class MaskOverlap(OverlapMeasure[dict]):
    """Mask IoU on ``pycocotools`` run-length encodings (no motion)."""

    def states(self, detections: Any) -> list[dict]:
        """The RLE of each mask of an ``(m, H, W)`` bool stack."""
        from unitrack_env.datasets.rle import mask_api as mask_utils

        masks = np.asarray(detections, dtype=bool)
        if not len(masks):
            return []
        return list(mask_utils.encode(np.asfortranarray(masks.transpose(1, 2, 0).astype(np.uint8))))

    def similarity(self, a: Sequence[dict], b: Sequence[dict]) -> np.ndarray:
        """Mask IoU (no crowd regions)."""
        from unitrack_env.datasets.rle import mask_api as mask_utils

        return np.asarray(mask_utils.iou(list(a), list(b), [False] * len(b))
                          ).reshape(len(a), len(b))


class PoseOverlap(OverlapMeasure[np.ndarray]):
    """Object keypoint similarity (:func:`object_keypoint_similarity`; no motion)."""

    def __init__(self, sigmas: np.ndarray = OKS_SIGMAS) -> None:
        self.sigmas = sigmas

    def states(self, detections: Any) -> list[np.ndarray]:
        """The poses of an ``(m, K, 3)`` array."""
        return list(np.asarray(detections))

    def similarity(self, a: Sequence[np.ndarray], b: Sequence[np.ndarray]) -> np.ndarray:
        """OKS of ``a``'s poses (their areas) against ``b``'s."""
        return object_keypoint_similarity(np.stack(a), np.stack(b), self.sigmas)
