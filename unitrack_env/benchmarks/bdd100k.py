"""BDD100K box tracking (8 classes): TrackEval's HOTA, CLEAR, Identity per class and combined."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from unitrack_env.benchmarks.base import Benchmark, data_root, rounded_digest
from unitrack_env.benchmarks.kitti import flat_metrics
from unitrack_env.datasets.bdd100k import (
    CLASSES,
    SUPER_CATEGORIES,
    BDD100KDataset,
    read_bdd_frames,
)
from unitrack_env.datasets.synthetic.bdd100k import KIND
from unitrack_env.io import atomic_write_text
from unitrack_env.metrics.report import ScoreReport

#: Result rows: ``frame (0-based), id, class id (1 + index in CLASSES), x1, y1, x2, y2, score``.
RESULT_COLUMNS = 8


def format_bdd_results(sequence: str, rows: np.ndarray, length: int) -> str:
    """Rows as a Scalabel JSON list of ``length`` frames (ids and categories as BDD's)."""
    rows = np.asarray(rows, dtype=np.float64).reshape(-1, RESULT_COLUMNS)
    frames = []
    for t in range(length):
        labels = [{"id": str(int(i)), "category": CLASSES[int(c) - 1],
                   "box2d": {"x1": x1, "y1": y1, "x2": x2, "y2": y2}, "score": s}
                  for _, i, c, x1, y1, x2, y2, s in rows[rows[:, 0] == t].tolist()]
        frames.append({"name": f"{sequence}-{t + 1:07d}.jpg", "videoName": sequence,
                       "frameIndex": t, "labels": labels})
    return json.dumps(frames)


class BDD100KBenchmark(Benchmark):
    """BDD100K box-tracking scoring with TrackEval's ``BDD100K`` dataset class.

    ``results`` of one sequence: ``(k, 8)`` rows (see :data:`RESULT_COLUMNS`), written as
    ``<folder>/<sequence>.json`` in Scalabel's format. Metrics: TrackEval's per class
    (``car/HOTA``, ...), per super-category (``VEHICLE/HOTA``, ...), class-averaged
    (``cls_comb_cls_av/HOTA``) and detection-averaged (``cls_comb_det_av/HOTA``, also
    unprefixed: ``HOTA``).
    """

    task = "mot"
    columns = ("HOTA", "cls_comb_cls_av/HOTA", "car/HOTA", "pedestrian/HOTA", "MOTA",
               "cls_comb_cls_av/MOTA", "IDF1", "cls_comb_cls_av/IDF1", "IDSW")

    @classmethod
    def build(cls, root: str | os.PathLike | None = None, split: str = "val",
              detections: str | os.PathLike | None = None) -> BDD100KBenchmark:
        """The benchmark of ``BDD100KEnv(root=, split=, detections=)``.

        ``root`` holds ``labels/box_track_20/<split>``; default ``$UNITRACK_DATA/BDD100K``,
        else the synthetic split.
        """
        path, synthetic = data_root(root, "BDD100K", "BDD100K", KIND)
        return cls(BDD100KDataset(path, split, detections), synthetic=synthetic)

    @property
    def name(self) -> str:
        """``"BDD100K"``."""
        return "BDD100K"

    def sequence_length(self, name: str) -> int:
        """Frames of ``name`` (its ground truth's last ``frameIndex`` + 1)."""
        return self.dataset.lengths[name]

    def has_ground_truth(self, name: str) -> bool:
        """Whether ``name`` has its JSON file (every listed sequence has)."""
        return name in self.dataset.files

    def write(self, folder: str | os.PathLike, sequence: str, results: np.ndarray) -> None:
        """Write ``<folder>/<sequence>.json`` in Scalabel's format."""
        atomic_write_text(Path(folder) / f"{sequence}.json",
                          format_bdd_results(sequence, results, self.sequence_length(sequence)))

    def read(self, folder: str | os.PathLike, sequence: str) -> np.ndarray:
        """Read ``<folder>/<sequence>.json`` back as ``(k, 8)`` rows (ids numbered from 1)."""
        frames = read_bdd_frames(Path(folder) / f"{sequence}.json", results=True,
                                 length=self.sequence_length(sequence))
        numbers: dict[str, int] = {}
        rows = [(t, numbers.setdefault(label.ident, len(numbers) + 1),
                 CLASSES.index(label.category) + 1, *label.box, label.score)
                for t, labels in enumerate(frames) for label in labels]
        return np.asarray(rows, dtype=np.float64).reshape(-1, RESULT_COLUMNS)

    def digest(self, results: np.ndarray) -> str:
        """SHA-256 of the rows rounded to 1e-3."""
        return rounded_digest(results)

    def _combined(self, folder: Path, sequences: list[str]) -> tuple[dict, dict]:
        """TrackEval's raw scores per sequence and their combination."""
        # lazy: start-up cost (scipy, via unitrack_env.metrics.bdd100k and .kitti)
        from unitrack_env.metrics.bdd100k import bdd_raw_scores
        from unitrack_env.metrics.kitti import combine

        raw = bdd_raw_scores({seq: self.dataset.ground_truth_path(seq) for seq in sequences},
                             folder)
        return raw, combine(raw, CLASSES, SUPER_CATEGORIES)

    def score_sequence(self, sequence: str, results: np.ndarray) -> dict[str, float]:
        """TrackEval's metrics of one sequence's rows."""
        import tempfile

        with tempfile.TemporaryDirectory(prefix="unitrack-bdd-seq-") as tmp:
            self.write(tmp, sequence, results)
            return flat_metrics(self._combined(Path(tmp), [sequence])[1])

    def score_files(self, folder: str | os.PathLike, sequences: list[str]) -> ScoreReport:
        """Score ``<folder>/<sequence>.json`` files: per sequence and over all of them."""
        # lazy: start-up cost (scipy, via unitrack_env.metrics.kitti)
        from unitrack_env.metrics.kitti import combine

        raw, combined = self._combined(Path(folder), sequences)
        per_sequence = {seq: flat_metrics(combine({seq: raw[seq]}, CLASSES, SUPER_CATEGORIES))
                        for seq in sequences}
        return ScoreReport(self.name, per_sequence, flat_metrics(combined),
                           scores={"per_class": combined})

    def frame_image(self, sequence: str, frame: int) -> Path:
        """``images/track/<split>/<video>/<video>-<frame>.jpg`` (``frame`` from 1)."""
        return self.dataset.frame_path(sequence, frame - 1)

    def frame_rate(self, sequence: str) -> float:
        """BDD100K's box-track annotation rate, 5 fps."""
        return 5.0
