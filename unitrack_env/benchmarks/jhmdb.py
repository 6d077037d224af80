"""The JHMDB pose propagation benchmark: PCK at the paper's thresholds."""

from __future__ import annotations

import os
from pathlib import Path
from types import MappingProxyType

import numpy as np

from unitrack_env.benchmarks.base import Benchmark, data_root, rounded_digest
from unitrack_env.benchmarks.views import Head, ReportView, ScorecardColumn
from unitrack_env.datasets.jhmdb import JHMDBDataset, read_joint_positions
from unitrack_env.errors import DataFormatError
from unitrack_env.io import atomic_write_bytes
from unitrack_env.metrics.events_mot import EventRows
from unitrack_env.metrics.pose import (
    NORMALISERS,
    PAPER_PCK_THRESHOLDS,
    PCKCounts,
    frame_pck,
    pck_counts,
)
from unitrack_env.metrics.report import COMBINED, ScoreReport

#: Name of a sequence's ground-truth and result file.
RESULT_FILE = "joint_positions.mat"


def pose_mat_bytes(keypoints: np.ndarray) -> bytes:
    """Return a ``joint_positions.mat`` (``pos_img`` ``(2, 15, T)``, 1-based) for 0-based joints."""
    # lazy: start-up cost (unitrack_env.datasets.synthetic, every generator)
    from unitrack_env.datasets.synthetic.jhmdb import joint_positions_mat

    return joint_positions_mat(keypoints)


class JHMDBBenchmark(Benchmark):
    """PCK of the propagated joints (frame 1 not scored); ``COMBINED`` pools all joints.

    ``results`` of one video: the ``(frames, 15, 2)`` joints in 0-based pixels, written as
    ``<folder>/<action>/<video>/joint_positions.mat`` (``pos_img``, 1-based, as JHMDB ships).
    """

    task = "pose-prop"
    columns = ("PCK@0.1", "PCK@0.2")
    report_view = ReportView(value=("pck", "PCK@0.1"))
    intervals = "frames"  # PCK pools the joints of every frame (frames pooled to combine)
    frame_metrics = MappingProxyType({"PCK@0.1": lambda d: d["pck"].to_numpy()})
    scorecard = ScorecardColumn(
        "Pose prop.", ("UniTrack/JHMDB-v0",),
        (Head("unitrack-pose", "UniTrack", ("PCK@0.1", "PCK@0.2")),),
        Head("repeat-pose", "repeat-pose", ("PCK@0.1", "PCK@0.2"), appearance=False),
        ("UniTrack", "PCK@0.1"), order=6, input_size=(1, 240, 320), head_seconds=0.15)

    def __init__(self, dataset: JHMDBDataset, normaliser: str = "box_diagonal",
                 thresholds: tuple[float, ...] = PAPER_PCK_THRESHOLDS, *,
                 synthetic: bool = False) -> None:
        super().__init__(dataset, synthetic=synthetic)
        if normaliser not in NORMALISERS:
            raise ValueError(f"normaliser must be one of {NORMALISERS}; got {normaliser!r}")
        self.normaliser = normaliser
        self.thresholds = tuple(float(t) for t in thresholds)

    @classmethod
    def build(cls, root: str | os.PathLike | None = None, split: str | None = None,
              split_index: int = 1, split_dir: str | os.PathLike | None = None,
              normaliser: str = "box_diagonal",
              thresholds: tuple[float, ...] = PAPER_PCK_THRESHOLDS) -> JHMDBBenchmark:
        """The benchmark of ``JHMDBEnv(root=, split=, normaliser=, thresholds=, ...)``."""
        path, synthetic = data_root(root, "JHMDB", "JHMDB", kind="jhmdb")
        return cls(JHMDBDataset(path, split, split_index, split_dir), normaliser, thresholds,
                   synthetic=synthetic)

    @property
    def name(self) -> str:
        """``"JHMDB"``."""
        return "JHMDB"

    def ground_truth(self, name: str) -> np.ndarray:
        """The ``(frames, 15, 2)`` annotated joints of video ``name`` (0-based)."""
        return read_joint_positions(self.dataset.joint_dir / name / RESULT_FILE)

    def sequence_length(self, name: str) -> int:
        """Number of annotated frames of ``name`` (reads only its ``.mat``)."""
        return len(self.ground_truth(name))

    def has_ground_truth(self, name: str) -> bool:
        """Every JHMDB video is annotated."""
        return name in self.dataset.sequence_names

    def write(self, folder: str | os.PathLike, sequence: str, results: np.ndarray) -> None:
        """Write ``<folder>/<action>/<video>/joint_positions.mat`` (``pos_img``, 1-based)."""
        atomic_write_bytes(Path(folder) / sequence / RESULT_FILE, pose_mat_bytes(results))

    def read(self, folder: str | os.PathLike, sequence: str) -> np.ndarray:
        """Read ``<folder>/<sequence>/joint_positions.mat`` as 0-based joints."""
        return read_joint_positions(Path(folder) / sequence / RESULT_FILE)

    def digest(self, results: np.ndarray) -> str:
        """SHA-256 of the joints rounded to 1e-3 px."""
        return rounded_digest(results)

    def counts(self, predictions: np.ndarray, ground_truth: np.ndarray) -> PCKCounts:
        """PCK counts of predicted joints against ground truth (same frames)."""
        return pck_counts(predictions, ground_truth, self.thresholds, method=self.normaliser)

    def score_sequence(self, sequence: str, results: np.ndarray) -> dict[str, float]:
        """PCK at every threshold of one video's joints (frame 1 not scored)."""
        return self.counts(results, self.ground_truth(sequence)[: len(results)]).as_dict()

    def score_files(self, folder: str | os.PathLike, sequences: list[str]) -> ScoreReport:
        """Score ``<folder>/<name>/joint_positions.mat`` files (each covering its video)."""
        per_sequence: dict[str, dict[str, float]] = {}
        pooled: PCKCounts | None = None
        for name in sequences:
            pred = self.read(folder, name)
            gt = self.ground_truth(name)
            if pred.shape != gt.shape:
                raise DataFormatError(Path(folder) / name / RESULT_FILE,
                                      f"holds {len(pred)} frames, the video has {len(gt)}",
                                      field="pos_img")
            counts = self.counts(pred, gt)
            per_sequence[name] = counts.as_dict()
            pooled = counts if pooled is None else pooled.merge(counts)
        combined = pooled.as_dict() if pooled is not None else {}
        return ScoreReport("JHMDB", per_sequence, combined,
                           scores={**per_sequence, COMBINED: combined})

    def sequence_events(self, folder: str | os.PathLike, sequence: str) -> EventRows:
        """One ``"frame"`` event per scored frame: its PCK at 0.1."""
        pred, gt = self.read(folder, sequence), self.ground_truth(sequence)
        rows = EventRows(sequence)
        for t in range(1, min(len(pred), len(gt))):  # frame 1 is given, and not scored
            rows.add(t + 1, "frame", pck=frame_pck(pred[t], gt[t], method=self.normaliser))
        return rows
