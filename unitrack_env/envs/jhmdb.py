"""Pose propagation on JHMDB (frames + ``joint_positions.mat``, 15 puppet joints)."""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from gymnasium import spaces
from typing_extensions import Unpack

from unitrack_env import spaces as ut_spaces
from unitrack_env.benchmarks.jhmdb import JHMDBBenchmark
from unitrack_env.datasets.jhmdb import JHMDB_SKELETON, NUM_JOINTS, PoseSequence
from unitrack_env.envs.base import EpisodeOptions, SequenceEnv
from unitrack_env.errors import InvalidActionError
from unitrack_env.metrics.pose import PAPER_PCK_THRESHOLDS, frame_pck
from unitrack_env.render import draw_skeleton

#: PCK threshold of the per-step reward.
REWARD_ALPHA = 0.1


class JHMDBEnv(SequenceEnv[PoseSequence]):
    """Pose propagation: follow one person's 15 joints through a JHMDB video.

    Spaces, rewards, metrics and arguments: docs/envs/jhmdb.md.
    """

    frame_size_source = "the video's first frame"

    def __init__(
        self,
        root: str | os.PathLike | None = None,
        split: str | None = None,
        split_index: int = 1,
        split_dir: str | os.PathLike | None = None,
        sequences: list[str] | tuple[str, ...] | None = None,
        normaliser: str = "box_diagonal",
        thresholds: tuple[float, ...] = PAPER_PCK_THRESHOLDS,
        **options: Unpack[EpisodeOptions],
    ) -> None:
        super().__init__(**options)
        bench = JHMDBBenchmark.build(root, split, split_index, split_dir, normaliser, thresholds)
        self._use_benchmark(bench, sequences, bench.dataset.root)
        self.normaliser = normaliser
        self.thresholds = tuple(float(t) for t in thresholds)
        joints = spaces.Box(-ut_spaces.COORD_MAX, ut_spaces.COORD_MAX, (NUM_JOINTS, 2),
                            np.float32)
        self.observation_space = spaces.Dict(
            {"frame": ut_spaces.Image(*self.max_frame_size), "init_keypoints": joints})
        self.action_space = spaces.Box(-ut_spaces.COORD_MAX, ut_spaces.COORD_MAX,
                                       (NUM_JOINTS, 2), np.float32)
        self._predictions: list[np.ndarray] = []

    # ------------------------------------------------------------------ episode hooks
    def _load(self, name: str) -> dict[str, Any]:
        sequence = self.dataset.load(name)
        width, height = sequence.image_size
        self._check_frame_size(name, width, height, axes=False)
        self._sequence = sequence
        self._predictions = []
        return dict(seq_length=sequence.num_frames, frame_rate=30, image_size=(height, width),
                    synthetic=self.synthetic, has_ground_truth=True)

    def _observe(self, t: int) -> dict[str, Any]:
        image = self._read_frame(t)
        return {"frame": image, "init_keypoints": self._sequence.init_keypoints.astype(np.float32)}

    def _frame_info(self, t: int) -> dict[str, Any]:
        return {"frame_index": t + 1}

    def _record(self, action: Any, t: int) -> tuple[float, dict[str, Any]]:
        """Record frame ``t``'s joints; the reward is PCK@0.1 (frame 1 is not scored)."""
        pred = _validate_joints(action)
        self._predictions.append(pred)
        self._answer = pred
        if t == 0:
            return 0.0, {}
        reward = frame_pck(pred, self._sequence.keypoints[t], REWARD_ALPHA, self.normaliser)
        return reward, {"pck": reward}

    # ------------------------------------------------------------------ results
    def episode_results(self) -> np.ndarray:
        """Return the ``(steps, 15, 2)`` joints recorded so far (0-based pixels)."""
        if not self._predictions:
            return np.zeros((0, NUM_JOINTS, 2))
        return np.stack(self._predictions)

    def episode_metrics(self) -> dict[str, float]:
        """PCK at every threshold of the recorded video (frame 1 not scored)."""
        pred = self.episode_results()
        return self.scoring.counts(pred, self._sequence.keypoints[: len(pred)]).as_dict()

    # ------------------------------------------------------------------ rendering
    def _draw(self) -> np.ndarray:
        """Return the frame with the last predicted skeleton (``init_keypoints`` at reset)."""
        canvas = np.ascontiguousarray(self._frame).copy()
        pose = self._answer if self._answer is not None else self._sequence.keypoints[0]
        draw_skeleton(canvas, pose, JHMDB_SKELETON)
        return canvas


def _validate_joints(action: Any) -> np.ndarray:
    """Return the action as ``(15, 2)`` float64, or raise InvalidActionError."""
    arr = np.asarray(action)
    if arr.shape != (NUM_JOINTS, 2):
        raise InvalidActionError(
            f"action must be the ({NUM_JOINTS}, 2) predicted joints (x, y); got shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise InvalidActionError(f"action must hold numbers, got dtype {arr.dtype}")
    arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        joint = int(np.argwhere(~np.isfinite(arr))[0, 0])
        raise InvalidActionError(f"joint {joint} is NaN or infinite: {arr[joint].tolist()}")
    if np.abs(arr).max() > ut_spaces.COORD_MAX:
        joint = int(np.argwhere(np.abs(arr) > ut_spaces.COORD_MAX)[0, 0])
        raise InvalidActionError(
            f"joint {joint} {arr[joint].tolist()} is outside the action space: x and y must lie "
            f"in [-{ut_spaces.COORD_MAX:g}, {ut_spaces.COORD_MAX:g}] pixels")
    return arr
