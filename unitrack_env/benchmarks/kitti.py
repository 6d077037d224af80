"""KITTI tracking (Car, Pedestrian): TrackEval's HOTA, CLEAR, Identity per class and combined."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from unitrack_env.benchmarks.base import Benchmark, data_root, rounded_digest
from unitrack_env.datasets.kitti_tracking import (
    CLASS_IDS,
    KITTITrackingDataset,
    read_kitti_rows,
)
from unitrack_env.datasets.synthetic.kitti import KIND
from unitrack_env.io import atomic_write_text
from unitrack_env.metrics.report import ScoreReport

#: Result rows: ``frame (0-based), id, class id (1 Car, 2 Pedestrian), x1, y1, x2, y2, score``.
RESULT_COLUMNS = 8
_NAMES = {ident: name for name, ident in CLASS_IDS.items()}
#: The metrics given per class and for both class combinations (prefixed ``<class>/``).
PER_CLASS_METRICS = ("HOTA", "DetA", "AssA", "MOTA", "IDF1", "IDSW")


def format_kitti_results(rows: np.ndarray) -> str:
    """Rows as KITTI tracking result lines (17 columns and the score; 3D fields unknown)."""
    lines = [f"{int(f)} {int(i)} {_NAMES[int(c)]} -1 -1 -10 {x1:.2f} {y1:.2f} {x2:.2f} {y2:.2f} "
             f"-1 -1 -1 -1000 -1000 -1000 -10 {s:.4f}\n"
             for f, i, c, x1, y1, x2, y2, s in np.asarray(rows).reshape(-1, RESULT_COLUMNS)]
    return "".join(lines)


def flat_metrics(scores: dict[str, dict[str, float]]) -> dict[str, float]:
    """One row of metrics from :func:`unitrack_env.metrics.kitti.combine`'s output.

    Every metric of the detection-averaged combination unprefixed (TrackEval's
    ``cls_comb_det_av``), and :data:`PER_CLASS_METRICS` per class and per combination.
    """
    # lazy: start-up cost (scipy, via unitrack_env.metrics.kitti)
    from unitrack_env.metrics.kitti import DETECTION_AVERAGE

    row = dict(scores[DETECTION_AVERAGE])
    for key, values in scores.items():
        row.update({f"{key}/{name}": values[name] for name in PER_CLASS_METRICS})
    return row


class KITTIBenchmark(Benchmark):
    """KITTI tracking scoring with TrackEval's ``Kitti2DBox``.

    ``results`` of one sequence: ``(k, 8)`` rows (see :data:`RESULT_COLUMNS`), written as
    ``<folder>/<sequence>.txt`` in KITTI's result format. Metrics: TrackEval's per class
    (``car/HOTA``, ``pedestrian/HOTA``, ...), class-averaged (``cls_comb_cls_av/HOTA``) and
    detection-averaged (``cls_comb_det_av/HOTA``, also unprefixed: ``HOTA``).
    """

    task = "mot"
    columns = ("HOTA", "car/HOTA", "pedestrian/HOTA", "cls_comb_cls_av/HOTA", "MOTA",
               "car/MOTA", "pedestrian/MOTA", "IDF1", "car/IDF1", "pedestrian/IDF1", "IDSW")

    @classmethod
    def build(cls, root: str | os.PathLike | None = None, split: str = "training",
              detections: str | os.PathLike | None = None) -> KITTIBenchmark:
        """The benchmark of ``KITTIEnv(root=, split=, detections=)``."""
        path, synthetic = data_root(root, "KITTI", "KITTI", KIND)
        return cls(KITTITrackingDataset(path, split, detections), synthetic=synthetic)

    @property
    def name(self) -> str:
        """``"KITTI"``."""
        return "KITTI"

    def sequence_length(self, name: str) -> int:
        """Frames of ``name`` (the seqmap's, else its number of images)."""
        return self.dataset.lengths[name]

    def has_ground_truth(self, name: str) -> bool:
        """Whether ``label_02/<name>.txt`` exists."""
        return self.dataset.has_ground_truth(name)

    def write(self, folder: str | os.PathLike, sequence: str, results: np.ndarray) -> None:
        """Write ``<folder>/<sequence>.txt`` in KITTI's result format."""
        atomic_write_text(Path(folder) / f"{sequence}.txt", format_kitti_results(results))

    def read(self, folder: str | os.PathLike, sequence: str) -> np.ndarray:
        """Read ``<folder>/<sequence>.txt`` back as ``(k, 8)`` rows (Car and Pedestrian)."""
        rows = read_kitti_rows(Path(folder) / f"{sequence}.txt", self.sequence_length(sequence),
                               min_columns=10)
        keep = np.isin(rows.types, list(CLASS_IDS))
        classes = np.array([CLASS_IDS[t] for t in rows.types[keep]], dtype=np.float64)
        return np.column_stack([rows.frames[keep], rows.ids[keep], classes, rows.boxes[keep],
                                rows.scores[keep]]).reshape(-1, RESULT_COLUMNS)

    def digest(self, results: np.ndarray) -> str:
        """SHA-256 of the rows rounded to 1e-3."""
        return rounded_digest(results)

    def _scores(self, folder: Path, sequences: list[str]) -> dict:
        # lazy: start-up cost (scipy, via unitrack_env.metrics.kitti)
        from unitrack_env.metrics.kitti import kitti_raw_scores

        return kitti_raw_scores(self.dataset.split_dir / "label_02", folder,
                                {name: self.sequence_length(name) for name in sequences})

    def score_sequence(self, sequence: str, results: np.ndarray) -> dict[str, float]:
        """TrackEval's metrics of one sequence's rows."""
        import tempfile

        # lazy: start-up cost (scipy, via unitrack_env.metrics.kitti)
        from unitrack_env.metrics.kitti import combine

        with tempfile.TemporaryDirectory(prefix="unitrack-kitti-seq-") as tmp:
            self.write(tmp, sequence, results)
            return flat_metrics(combine(self._scores(Path(tmp), [sequence])))

    def score_files(self, folder: str | os.PathLike, sequences: list[str]) -> ScoreReport:
        """Score ``<folder>/<sequence>.txt`` files: per sequence and over all of them."""
        # lazy: start-up cost (scipy, via unitrack_env.metrics.kitti)
        from unitrack_env.metrics.kitti import combine

        for seq in sequences:  # a bad file is named with its line and field, not TrackEval's
            self.read(folder, seq)
        raw = self._scores(Path(folder), sequences)
        per_sequence = {seq: flat_metrics(combine({seq: raw[seq]})) for seq in sequences}
        combined = combine(raw)
        return ScoreReport(self.name, per_sequence, flat_metrics(combined),
                           scores={"per_class": combined})

    def frame_image(self, sequence: str, frame: int) -> Path:
        """``image_02/<sequence>/<frame>.png`` (frames from 0)."""
        return self.dataset.split_dir / "image_02" / sequence / f"{frame:06d}.png"

    def frame_rate(self, sequence: str) -> float:
        """KITTI's camera rate, 10 fps."""
        return 10.0
