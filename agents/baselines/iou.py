"""The IoU baseline: overlap + Hungarian matching with a track life cycle, no appearance.

An observation adapter around an
:class:`~unitrack_env.agents.primitives.overlap.OverlapTracker` whose measure fits
the task: box IoU with a constant-velocity guess (MOT), mask IoU (MOTS, VIS), OKS (PoseTrack).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..base import Agent
from ..primitives.adapters import (
    ObservationAdapter,
    detect_task,
    episode_adapter,
)
from ..primitives.overlap import (
    BoxOverlap,
    MaskOverlap,
    OverlapMeasure,
    OverlapTracker,
    PoseOverlap,
)

__all__ = ["IoUAgent", "IoUConfig"]


@dataclass(frozen=True)
class IoUConfig:
    """Parameters of the IoU baseline.

    Attributes:
        iou_threshold: Least IoU between a track's predicted box and a detection to match.
        min_hits: Matches before a track is reported (all are during the first ``min_hits``
            frames).
        max_lost_seconds: How long a track that found no detection is kept.
        velocity_smoothing: Weight of the newest displacement in the smoothed velocity (0: none).
        duplicate_iou: An unmatched detection overlapping a matched one this much starts no
            track (1 = off).
        oks_threshold: Poses: least OKS to match (low: fast motion lowers a person's OKS with
            itself; the sweep is in docs/design-decisions.md).
        duplicate_oks: Poses: the duplicate OKS (1 = off).
    """

    iou_threshold: float = 0.3
    min_hits: int = 2
    max_lost_seconds: float = 1.0
    velocity_smoothing: float = 0.5
    duplicate_iou: float = 0.3
    oks_threshold: float = 0.2
    duplicate_oks: float = 0.8


class IoUAgent(Agent, name="iou", tasks=("mot", "mots", "vis", "posetrack")):
    """Associates detections to tracks by overlap, without appearance.

    Per frame: predict each track, Hungarian-match on the overlap, start a track for each
    unmatched non-duplicate detection, drop tracks lost over ``max_lost_seconds``; only tracks
    matched in this frame are reported. ``max_tracks``: the action capacity of box and pose
    tasks (None: the reset info's); ``**config``: :class:`IoUConfig` fields.
    """

    config_class = IoUConfig

    def __init__(self, max_tracks: int | None = None, **config: Any) -> None:
        self.config = IoUConfig(**config)
        self._max_tracks = max_tracks
        self._from_info = False
        self._start("mot", {}, 30.0)

    @property
    def task(self) -> str:
        """The task being played."""
        return self.adapter.task

    @property
    def max_tracks(self) -> int:
        """Action capacity of box and pose tracks."""
        return self.adapter.max_tracks

    def _start(self, task: str, info: dict[str, Any], frame_rate: float) -> None:
        """Set up the adapter and the tracker of ``task`` for a new episode."""
        self._frame_rate = frame_rate
        self.adapter: ObservationAdapter = episode_adapter(
            None, {**info, "task": task}, task, self._max_tracks)
        cfg = self.config
        poses = self.adapter.kind == "poses"
        measure: OverlapMeasure[Any] = PoseOverlap() if poses else (
            MaskOverlap() if self.adapter.kind == "masks"
            else BoxOverlap(cfg.velocity_smoothing))
        self.tracker: OverlapTracker[Any] = OverlapTracker(
            measure, threshold=cfg.oks_threshold if poses else cfg.iou_threshold,
            duplicate_threshold=cfg.duplicate_oks if poses else cfg.duplicate_iou,
            min_hits=cfg.min_hits, max_lost_seconds=cfg.max_lost_seconds,
            frame_rate=frame_rate)

    def reset(self, observation: Any, info: dict[str, Any]) -> None:
        """Forget all tracks; read the task, the capacities and the frame rate."""
        self._from_info = bool(info.get("task"))
        task = episode_adapter(observation, info, self.task).task
        self._start(task, info, float(info.get("frame_rate", 30.0)))

    def act(self, observation: dict[str, Any]) -> dict[str, Any]:
        """Match this frame's detections to the tracks and report the matched tracks."""
        if not self._from_info and detect_task(observation) != self.task:
            # Reset without an environment's info: the observation tells the format.
            self._start(detect_task(observation), {"capacities": self.adapter.capacities},
                        self._frame_rate)
        detections = self.adapter.detections(observation)
        valid = np.arange(len(detections.scores))  # (score filtering: the env's min_score)
        if self.adapter.kind == "boxes":
            states = detections.boxes[valid]
        elif self.adapter.kind == "masks":
            states = detections.masks[valid]
        else:
            keypoints = np.asarray(detections.keypoints, dtype=np.float32)
            valid = valid[(keypoints[valid, :, 2] > 0).any(axis=1)]
            states = keypoints[valid]
        reports = self.tracker.step(self.tracker.measure.states(states))
        if self.adapter.kind == "poses":
            reports = sorted(reports, key=lambda r: r.detection_index)
        rows = valid[[r.detection_index for r in reports]]
        boxes = np.array([r.state for r in reports]).reshape(-1, 4) \
            if self.adapter.kind == "boxes" else None
        return self.adapter.action(detections, [r.track_id for r in reports], rows, boxes)
