"""What the MOT environments with classes share (KITTI tracking, BDD100K).

Each frame's detections carry a class id; the agent answers with the MOT envs' tracks; each
track takes the class of the detection it overlaps most in the frame (IoU > 0), else the
class it had last, else :attr:`ClassedMOTEnv.default_class`. The recorded results are the
``(k, 8)`` rows ``frame (0-based), id, class id, x1, y1, x2, y2, score`` that the KITTI and
BDD100K benchmarks write in their official formats.
"""

from __future__ import annotations

import abc
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar, NamedTuple

import numpy as np
from gymnasium import spaces
from typing_extensions import Unpack

from unitrack_env import spaces as ut_spaces
from unitrack_env.benchmarks.base import Benchmark
from unitrack_env.envs.base import EpisodeOptions, SequenceEnv, SequenceT
from unitrack_env.envs.track_classes import track_classes
from unitrack_env.errors import DataFormatError
from unitrack_env.render import draw_boxes

#: Capacities of the padded arrays, those of the MOT envs (agents of the task assume them).
DEFAULT_MAX_DETECTIONS = 512
DEFAULT_MAX_TRACKS = 512
#: Columns of a result row.
RESULT_COLUMNS = 8


class FrameDetections(NamedTuple):
    """One frame's detections: boxes ``(n, 4)`` as ``(x, y, w, h)``, scores, class ids."""

    boxes: np.ndarray
    scores: np.ndarray
    classes: np.ndarray

    @classmethod
    def from_corners(cls, corners: Sequence[Sequence[float]], scores: Sequence[float],
                     classes: Sequence[int]) -> FrameDetections:
        """From ``(x1, y1, x2, y2)`` boxes."""
        boxes = np.array(corners, dtype=np.float64).reshape(-1, 4)
        boxes[:, 2:] -= boxes[:, :2]
        return cls(boxes, np.asarray(scores, dtype=np.float64).reshape(-1),
                   np.asarray(classes, dtype=np.int64).reshape(-1))


class ClassedMOTEnv(SequenceEnv[SequenceT]):
    """Base class: MOT by association over detections with classes (see the module docstring).

    A subclass names its benchmark (whose ``build(root, split, detections)`` reads the data
    set: ``split_dir``, ``detection_path(name)``, ``load(name, check_frames=)``), its classes
    and its default split, and gives a loaded sequence's detections frame by frame
    (:meth:`_frame_detections_of`).
    """

    #: The benchmark class, built from ``root``, ``split`` and ``detections``.
    benchmark_class: ClassVar[type[Benchmark]]
    #: The split played when ``split`` is not given.
    default_split: ClassVar[str]
    #: What the refusal of a data set without detections advises.
    detections_advice: ClassVar[str]
    #: Class ids in observations and results run from 1 to this.
    num_classes: ClassVar[int]
    #: The class of a track that never overlapped a detection.
    default_class: ClassVar[int] = 1

    def __init__(self, root: str | os.PathLike | None = None, split: str | None = None,
                 detections: str | os.PathLike | None = None,
                 sequences: list[str] | tuple[str, ...] | None = None,
                 max_detections: int = DEFAULT_MAX_DETECTIONS,
                 max_tracks: int = DEFAULT_MAX_TRACKS,
                 **options: Unpack[EpisodeOptions]) -> None:
        super().__init__(**options)
        bench = self.benchmark_class.build(root, split or self.default_split, detections)
        self._use_benchmark(bench, sequences, bench.dataset.split_dir)
        self._check_sequences()
        missing = [n for n in self.sequence_names
                   if not self.dataset.detection_path(n).is_file()]
        if missing:  # before any frame
            raise DataFormatError(self.dataset.detection_path(missing[0]),
                                  f"no detections: {self.detections_advice} (missing for "
                                  f"{', '.join(missing)})")
        self.max_detections, self.max_tracks = int(max_detections), int(max_tracks)
        observation = ut_spaces.detection_observation_space(self.max_detections,
                                                            self.max_frame_size)
        observation.spaces["classes"] = spaces.Box(0, self.num_classes, (self.max_detections,),
                                                   np.int64)
        self.observation_space = observation
        self.action_space = ut_spaces.track_action_space(self.max_tracks)
        self._results: list[np.ndarray] = []
        self._track_class: dict[int, int] = {}
        self._detections: list[FrameDetections] = []

    def _check_sequences(self) -> None:
        """Refuse, at construction, what the chosen sequences lack to be played (default: none)."""

    @abc.abstractmethod
    def _frame_detections_of(self, sequence: SequenceT) -> list[FrameDetections]:
        """The detections of each frame of a loaded sequence, of the evaluated classes."""

    def _load(self, name: str) -> dict[str, Any]:
        sequence = self.dataset.load(name, check_frames=self.decode_frames)
        self._check_frame_size(name, *sequence.size)
        detections = self._frame_detections_of(sequence)
        most = max((len(d.boxes) for d in detections), default=0)
        if most > self.max_detections:
            raise ValueError(f"{self.dataset.detection_path(name)}: a frame has {most} "
                             f"detections, more than max_detections={self.max_detections}")
        self._sequence, self._detections = sequence, detections
        self._results, self._track_class = [], {}
        return dict(seq_length=sequence.length, frame_rate=self.scoring.frame_rate(name),
                    image_size=(sequence.size[1], sequence.size[0]),
                    benchmark=self.scoring.name,
                    has_ground_truth=self.scoring.has_ground_truth(name),
                    synthetic=self.synthetic)

    # Sequences state ``length``, ``frame_path(t)`` (0-based) and ``size`` (width, height).
    def _length(self) -> int:
        return self._sequence.length

    def _frame_path(self, t: int) -> Path:
        return self._sequence.frame_path(t)

    def _frame_size(self) -> tuple[int, int]:
        return self._sequence.size

    def _frame_detections(self, t: int) -> FrameDetections:
        return self._detections[t]

    def _observe(self, t: int) -> dict[str, Any]:
        boxes, scores, classes = self._frame_detections(t)
        n = len(boxes)
        out = {"frame": self._read_frame(t),
               "boxes": np.zeros((self.max_detections, 4), np.float32),
               "scores": np.zeros(self.max_detections, np.float32),
               "classes": np.zeros(self.max_detections, np.int64), "num_detections": n}
        out["boxes"][:n], out["scores"][:n], out["classes"][:n] = boxes, scores, classes
        return out

    def _record(self, action: dict[str, Any], t: int) -> tuple[float, dict[str, Any]]:
        ids, boxes = ut_spaces.unpack_tracks(action, self.max_tracks)
        det_boxes, _, det_classes = self._frame_detections(t)
        classes = track_classes(ids, boxes, det_boxes, det_classes, self._track_class,
                                self.default_class)
        rows = np.empty((len(ids), RESULT_COLUMNS))
        for k, (track, box) in enumerate(zip(ids, boxes, strict=True)):
            x, y, w, h = (float(v) for v in box)
            rows[k] = (t, track, classes[k], x, y, x + w, y + h, 1.0)
        self._results.append(rows)
        self._answer = (ids, boxes)
        return 0.0, {}

    def episode_results(self) -> np.ndarray:
        """The recorded tracks as ``(k, 8)`` rows (see the module docstring)."""
        if not self._results:
            return np.zeros((0, RESULT_COLUMNS))
        return np.concatenate(self._results)

    def _draw(self) -> np.ndarray:
        if self._answer is None:
            return draw_boxes(self._frame, self._frame_detections(self._t).boxes)
        ids, boxes = self._answer
        return draw_boxes(self._answer_frame, boxes, ids)
