"""Multi-object tracking on KITTI tracking (Car and Pedestrian), scored with TrackEval."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from typing_extensions import Unpack

from unitrack_env import spaces as ut_spaces
from unitrack_env.benchmarks.kitti import RESULT_COLUMNS, KITTIBenchmark
from unitrack_env.datasets.kitti_tracking import CLASS_IDS, KITTISequence
from unitrack_env.envs.base import EpisodeOptions, SequenceEnv
from unitrack_env.errors import DataFormatError
from unitrack_env.geometry import box_iou
from unitrack_env.render import draw_boxes

#: Capacities of the padded arrays, those of the MOT envs (agents of the task assume them).
DEFAULT_MAX_DETECTIONS = 512
DEFAULT_MAX_TRACKS = 512


class KITTIEnv(SequenceEnv[KITTISequence]):
    """Multi-object tracking by association on KITTI tracking (Car and Pedestrian).

    ## Description
    Each episode is one sequence of KITTI tracking (``image_02/<seq>/%06d.png``,
    ``label_02/<seq>.txt``). At every step the agent sees one frame and that frame's
    detections of the evaluated classes, read from the user's detection files in KITTI's
    result format (KITTI ships none), and answers with its tracks as in the MOT envs. At the
    end, TrackEval's ``Kitti2DBox`` scores the sequence per class and combined.

    Without ``root`` (and ``$UNITRACK_DATA/KITTI``) it plays a small synthetic split in the
    exact layout, with its own detections (``training/det_02``).

    ## Observation space
    The MOT envs' ``Dict`` (``frame``, ``boxes`` ``(x, y, w, h)``, ``scores``,
    ``num_detections``) and ``classes``: ``(max_detections,) int64``, 1 Car, 2 Pedestrian.

    ## Action space
    The MOT envs' tracks (``ids``, ``boxes`` ``(x, y, w, h)``, ``num_tracks``). Each track
    takes the class of the detection it overlaps most in the frame (IoU > 0), else the class
    it had last, else Car.

    ## Rewards
    0 at every step: KITTI's preprocessing needs the whole frame's matching; the sequence's
    metrics come at the end.

    ## Episode end
    ``terminated=True`` after the last frame; ``info["metrics"]`` holds TrackEval's metrics
    of the sequence: detection-averaged over the classes unprefixed (``HOTA``, ``MOTA``,
    ...), and ``car/HOTA``, ``pedestrian/HOTA``, ``cls_comb_cls_av/HOTA``, ... .

    ## Arguments
    - ``root``: KITTI's tracking folder (holding ``training/``); default the synthetic split.
    - ``split``: ``"training"`` (or ``"testing"``, no ground truth).
    - ``detections``: a folder of ``<seq>.txt`` in KITTI's result format (default
      ``<root>/<split>/det_02``; refused at construction when there is none).
    - ``sequences``, ``max_detections``, ``max_tracks`` and the shared episode options.
    """

    requires = ("trackeval",)

    def __init__(self, root: str | os.PathLike | None = None, split: str = "training",
                 detections: str | os.PathLike | None = None,
                 sequences: list[str] | tuple[str, ...] | None = None,
                 max_detections: int = DEFAULT_MAX_DETECTIONS,
                 max_tracks: int = DEFAULT_MAX_TRACKS,
                 **options: Unpack[EpisodeOptions]) -> None:
        super().__init__(**options)
        bench = KITTIBenchmark.build(root, split, detections)
        self._use_benchmark(bench, sequences, bench.dataset.split_dir)
        missing = [n for n in self.sequence_names
                   if not bench.dataset.detection_path(n).is_file()]
        if missing:
            expected = bench.dataset.detection_path(missing[0])
            raise DataFormatError(expected, "no detections: KITTI ships none, pass "
                                  "detections=<a folder of <seq>.txt in KITTI's result format> "
                                  f"(missing for {', '.join(missing)})")
        self.max_detections, self.max_tracks = int(max_detections), int(max_tracks)
        observation = ut_spaces.detection_observation_space(self.max_detections,
                                                            self.max_frame_size)
        observation.spaces["classes"] = spaces.Box(0, 2, (self.max_detections,), np.int64)
        self.observation_space = observation
        self.action_space = ut_spaces.track_action_space(self.max_tracks)
        self._results: list[np.ndarray] = []
        self._track_class: dict[int, int] = {}
        self._keep = np.zeros(0, dtype=bool)

    def _load(self, name: str) -> dict[str, Any]:
        sequence = self.dataset.load(name, check_frames=self.decode_frames)
        self._check_frame_size(name, *sequence.size)
        dets = sequence.detections
        self._keep = np.isin(dets.types, list(CLASS_IDS))
        most = max((int(self._keep[dets.at(t)].sum()) for t in range(sequence.length)),
                   default=0)
        if most > self.max_detections:
            raise ValueError(f"{self.dataset.detection_path(name)}: a frame has {most} "
                             f"detections, more than max_detections={self.max_detections}")
        self._sequence, self._results, self._track_class = sequence, [], {}
        return dict(seq_length=sequence.length, frame_rate=10.0,
                    image_size=(sequence.size[1], sequence.size[0]), benchmark="KITTI",
                    has_ground_truth=sequence.ground_truth is not None,
                    synthetic=self.synthetic)

    def _length(self) -> int:
        return self._sequence.length

    def _frame_path(self, t: int) -> Path:
        return self._sequence.frame_path(t)

    def _frame_size(self) -> tuple[int, int]:
        return self._sequence.size

    def _frame_detections(self, t: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        dets = self._sequence.detections
        rows = dets.at(t)
        rows = rows[self._keep[rows]]
        boxes = dets.boxes[rows].copy()
        boxes[:, 2:] -= boxes[:, :2]
        classes = np.array([CLASS_IDS[k] for k in dets.types[rows]], dtype=np.int64)
        return boxes, dets.scores[rows], classes

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
        overlap = box_iou(np.asarray(boxes, np.float64).reshape(-1, 4), det_boxes) \
            if len(det_boxes) and len(ids) else np.zeros((len(ids), 0))
        rows = np.empty((len(ids), RESULT_COLUMNS))
        for k, (track, box) in enumerate(zip(ids, boxes, strict=True)):
            if overlap.shape[1] and overlap[k].max() > 0:
                self._track_class[int(track)] = int(det_classes[int(overlap[k].argmax())])
            x, y, w, h = (float(v) for v in box)
            rows[k] = (t, track, self._track_class.setdefault(int(track), 1), x, y, x + w,
                       y + h, 1.0)
        self._results.append(rows)
        self._answer = (ids, boxes)
        return 0.0, {}

    def episode_results(self) -> np.ndarray:
        """The recorded tracks as ``(k, 8)`` rows (see ``unitrack_env.benchmarks.kitti``)."""
        if not self._results:
            return np.zeros((0, RESULT_COLUMNS))
        return np.concatenate(self._results)

    def sequence_inputs(self, name: str) -> list[Path]:
        """The frames, the label file and the detection file of ``name``."""
        frames = sorted((self.dataset.split_dir / "image_02" / name).glob("*.png"))
        label = self.dataset.label_path(name)
        return [*frames, *([label] if label.is_file() else []),
                self.dataset.detection_path(name)]

    def _draw(self) -> np.ndarray:
        if self._answer is None:
            boxes, _, _ = self._frame_detections(self._t)
            return draw_boxes(self._frame, boxes)
        ids, boxes = self._answer
        return draw_boxes(self._answer_frame, boxes, ids)
