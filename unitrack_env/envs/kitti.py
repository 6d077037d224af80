"""Multi-object tracking on KITTI tracking (Car and Pedestrian), scored with TrackEval."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from unitrack_env.benchmarks.kitti import KITTIBenchmark
from unitrack_env.datasets.kitti_tracking import CLASS_IDS, KITTISequence
from unitrack_env.envs.classed_mot import ClassedMOTEnv, FrameDetections


class KITTIEnv(ClassedMOTEnv[KITTISequence]):
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
    benchmark_class = KITTIBenchmark
    default_split = "training"
    detections_advice = ("KITTI ships none, pass "
                                        "detections=<a folder of <seq>.txt in KITTI's result "
                                        "format>")
    num_classes = 2
    default_class = CLASS_IDS["Car"]

    def _frame_detections_of(self, sequence: KITTISequence) -> list[FrameDetections]:
        dets = sequence.detections
        keep = np.isin(dets.types, list(CLASS_IDS))
        frames = []
        for t in range(sequence.length):
            rows = dets.at(t)
            rows = rows[keep[rows]]
            frames.append(FrameDetections.from_corners(
                dets.boxes[rows], dets.scores[rows], [CLASS_IDS[k] for k in dets.types[rows]]))
        return frames

    def sequence_inputs(self, name: str) -> list[Path]:
        """The frames, the label file and the detection file of ``name``."""
        frames = sorted((self.dataset.split_dir / "image_02" / name).glob("*.png"))
        label = self.dataset.label_path(name)
        return [*frames, *([label] if label.is_file() else []),
                self.dataset.detection_path(name)]
