"""Multi-object tracking on MOTChallenge data (MOT15, MOT16, MOT17, MOT20, custom)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from typing_extensions import Unpack

from unitrack_env import spaces as ut_spaces
from unitrack_env.benchmarks.motchallenge import MOTChallengeBenchmark, result_rows
from unitrack_env.datasets.motchallenge import (
    Annotations,
    MOTSequence,
)
from unitrack_env.envs.base import EpisodeOptions, SequenceEnv
from unitrack_env.metrics.clear_stream import StreamingClear
from unitrack_env.metrics.mot_preprocess import preprocess_frame
from unitrack_env.render import draw_boxes

#: Default capacity of the padded detection arrays (MOT20 public detections reach ~250).
DEFAULT_MAX_DETECTIONS = 512
#: Default capacity of the padded track arrays.
DEFAULT_MAX_TRACKS = 512


class MOTChallengeEnv(SequenceEnv[MOTSequence]):
    """Multi-object tracking by association on a MOTChallenge-layout data set.

    Spaces, rewards, metrics and arguments: docs/envs/motchallenge.md.
    """

    requires = ("trackeval",)
    frame_size_source = "seqinfo.ini"

    def __init__(
        self,
        benchmark: str = "MOT17",
        root: str | os.PathLike | None = None,
        split: str = "train",
        sequences: list[str] | tuple[str, ...] | None = None,
        detections: str | os.PathLike = "public",
        min_score: float | None = None,
        max_detections: int = DEFAULT_MAX_DETECTIONS,
        max_tracks: int = DEFAULT_MAX_TRACKS,
        **options: Unpack[EpisodeOptions],
    ) -> None:
        super().__init__(**options)
        self.benchmark = benchmark
        bench = MOTChallengeBenchmark.build(benchmark, root, split, detections)
        self._use_benchmark(bench, sequences, bench.dataset.split_dir)
        self.min_score = min_score
        self.max_detections = int(max_detections)
        self.max_tracks = int(max_tracks)
        self.observation_space = ut_spaces.detection_observation_space(
            self.max_detections, self.max_frame_size
        )
        self.action_space: spaces.Dict = ut_spaces.track_action_space(self.max_tracks)

        self._detections: Annotations | None = None
        self._clear = StreamingClear()
        self._results: list[np.ndarray] = []

    # ------------------------------------------------------------------ episode hooks
    def _load(self, name: str) -> dict[str, Any]:
        sequence = self.dataset.load(name, check_frames=self.decode_frames)
        info = sequence.info
        self._check_frame_size(name, info.width, info.height)
        detections = sequence.detections
        if self.min_score is not None:
            detections = detections.filter(detections.scores >= self.min_score)
        most = int(detections.count_per_frame(info.length).max(initial=0))
        if most > self.max_detections:
            raise ValueError(
                f"{self.dataset.detection_path(name)}: a frame has {most} detections, more than "
                f"max_detections={self.max_detections}; pass a larger max_detections"
            )
        self._sequence = sequence
        self._detections = detections
        self._clear.reset()
        self._results = []
        return dict(seq_length=info.length, frame_rate=info.frame_rate,
                    image_size=(info.height, info.width), benchmark=self.benchmark,
                    has_ground_truth=sequence.ground_truth is not None,
                    synthetic=self.synthetic)

    def _first_step(self) -> int:
        return 1  # MOTChallenge frames are numbered from 1

    def _length(self) -> int:
        return self._sequence.info.length

    def _frame_path(self, t: int) -> Path:
        return self._sequence.info.frame_path(t)

    def _frame_size(self) -> tuple[int, int]:
        return self._sequence.info.width, self._sequence.info.height

    def _observe(self, t: int) -> dict[str, Any]:
        image = self._read_frame(t)
        rows = self._detections.rows(t)
        n = rows.stop - rows.start
        boxes = np.zeros((self.max_detections, 4), dtype=np.float32)
        scores = np.zeros(self.max_detections, dtype=np.float32)
        boxes[:n] = self._detections.boxes[rows]
        scores[:n] = self._detections.scores[rows]
        return {"frame": image, "boxes": boxes, "scores": scores, "num_detections": n}

    def _record(self, action: dict[str, Any], t: int) -> tuple[float, dict[str, Any]]:
        """Record the tracks of frame ``t`` and score them (``info["clear"]``)."""
        ids, boxes = ut_spaces.unpack_tracks(action, self.max_tracks)
        self._results.append(result_rows(t, ids, boxes))
        self._answer = (ids, boxes)
        gt = self._sequence.ground_truth
        if gt is None:
            return 0.0, {}
        rows = gt.rows(t)
        frame = preprocess_frame(
            gt.ids[rows], gt.boxes[rows], gt.classes[rows], gt.scores[rows].astype(np.int64),
            ids, boxes, self.benchmark,
        )
        counts = self._clear.update(
            frame.gt_ids, frame.gt_boxes, frame.tracker_ids, frame.tracker_boxes, iou=frame.iou
        )
        clear = {"tp": counts.tp, "fp": counts.fp, "fn": counts.fn, "idsw": counts.idsw}
        return float(counts.tp - counts.fp - counts.idsw), {"clear": clear}

    # ------------------------------------------------------------------ results
    def episode_results(self) -> np.ndarray:
        """Return the tracks recorded so far as MOTChallenge result rows.

        Columns: ``frame, id, x, y, w, h, conf, -1, -1, -1`` (``conf`` = 1), the official
        result format; write them with ``np.savetxt(..., delimiter=",")``.
        """
        if not self._results:
            return np.zeros((0, 10))
        return np.concatenate(self._results)

    def sequence_inputs(self, name: str) -> list[Path]:
        """The sequence's folder and its detection file (which may live elsewhere)."""
        return [*super().sequence_inputs(name), self.dataset.detection_path(name)]

    # ------------------------------------------------------------------ rendering
    def _draw(self) -> np.ndarray:
        """Return the current frame with id-coloured tracks (``rgb_array``), else None."""
        if self._answer is None:
            rows = self._detections.rows(self._t)
            return draw_boxes(self._frame, self._detections.boxes[rows])
        ids, boxes = self._answer
        return draw_boxes(self._answer_frame, boxes, ids)
