"""The PoseTrack 2018 benchmark: poseval's multi-person pose tracking metrics (MOTA, ...)."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

from unitrack_env.benchmarks.base import Benchmark, data_root
from unitrack_env.benchmarks.views import (
    LETTERBOX,
    ReportView,
    ScorecardColumn,
    association_head,
    iou_baseline,
)
from unitrack_env.datasets.posetrack import PoseTrackDataset
from unitrack_env.datasets.posetrack_json import read_posetrack_json, write_posetrack_json
from unitrack_env.datasets.posetrack_records import PoseTrackVideo
from unitrack_env.errors import DataFormatError
from unitrack_env.metrics.events_mot import EventRows
from unitrack_env.metrics.events_pose import posetrack_sequence_events
from unitrack_env.metrics.posetrack import evaluate_video, summarise
from unitrack_env.metrics.posetrack_frames import POSEVAL_DROPS_LAST_FRAME
from unitrack_env.metrics.report import COMBINED, ScoreReport

#: Name of the rule set in score reports (and the data folder under ``$UNITRACK_DATA``).
BENCHMARK = "PoseTrack2018"


class PoseTrackBenchmark(Benchmark):
    """PoseTrack 2018 tracking metrics (poseval: MOTA, IDF1, ... per keypoint, averaged).

    ``results`` of one sequence: a :class:`~unitrack_env.datasets.posetrack.PoseTrackVideo`
    holding the sequence's images and the tracked people of each frame, written as
    ``<folder>/<sequence>.json`` (the official result format).
    """

    task = "posetrack"
    columns = ("MOTA", "IDF1", "IDSW", "MOTP", "Precision", "Recall")
    report_view = ReportView(lanes=("fn", "fp", "idsw"), unit="joints")
    no_intervals = "poseval's metrics average per-joint scores, not means over frames"
    scorecard = ScorecardColumn(
        "PoseTrack", ("UniTrack/PoseTrack-v0",), (association_head(("IDF1", "MOTA", "IDSW")),),
        iou_baseline(("IDF1", "MOTA", "IDSW")), ("UniTrack", "IDF1"), frozenset({"IDSW"}),
        order=5, input_size=LETTERBOX)

    def __init__(self, dataset: PoseTrackDataset,
                 drop_last_frame: bool = POSEVAL_DROPS_LAST_FRAME, *,
                 synthetic: bool = False) -> None:
        super().__init__(dataset, synthetic=synthetic)
        self.drop_last_frame = bool(drop_last_frame)

    @classmethod
    def build(cls, root: str | os.PathLike | None = None, split: str = "val",
              drop_last_frame: bool = POSEVAL_DROPS_LAST_FRAME) -> PoseTrackBenchmark:
        """The benchmark of ``PoseTrackEnv(root=, split=, drop_last_frame=)``."""
        path, synthetic = data_root(root, BENCHMARK, BENCHMARK, kind="posetrack")
        return cls(PoseTrackDataset(path, split), drop_last_frame, synthetic=synthetic)

    @property
    def name(self) -> str:
        """``"PoseTrack2018"``."""
        return BENCHMARK

    def sequence_length(self, name: str) -> int:
        """Number of frames of ``name`` (its ``images`` entries or image files)."""
        return self.dataset.sequence_length(name)

    def has_ground_truth(self, name: str) -> bool:
        """Whether ``name`` has an annotation file."""
        return self.dataset.has_ground_truth(name)

    def write(self, folder: str | os.PathLike, sequence: str, results: PoseTrackVideo) -> None:
        """Write ``<folder>/<sequence>.json`` in the official PoseTrack 2018 result format."""
        write_posetrack_json(Path(folder) / f"{sequence}.json", results)

    def read(self, folder: str | os.PathLike, sequence: str) -> PoseTrackVideo:
        """Read ``<folder>/<sequence>.json``."""
        return read_posetrack_json(Path(folder) / f"{sequence}.json")

    def digest(self, results: PoseTrackVideo) -> str:
        """SHA-256 of the frame index, track id and keypoints (rounded to 1e-3) of each pose."""
        digest = hashlib.sha256()
        for k, people in enumerate(results.people):
            for person in people:
                row = np.concatenate([[k, person.track_id], person.keypoints.reshape(-1)])
                digest.update(np.round(row, 3).tobytes())
        return digest.hexdigest()

    def score_sequence(self, sequence: str, results: PoseTrackVideo) -> dict[str, float]:
        """Poseval's metrics of one sequence's tracked poses."""
        gt = read_posetrack_json(self.dataset.annotation_dir / f"{sequence}.json")
        return summarise([evaluate_video(gt, results, drop_last_frame=self.drop_last_frame)])

    def score_files(self, folder: str | os.PathLike, sequences: list[str]) -> ScoreReport:
        """Score ``<folder>/<sequence>.json`` result files with poseval's tracking metrics."""
        # Imported here: the metrics pull in scipy.optimize (0.5 s), which planning a run
        # (sequence names and lengths) does not need.

        per_sequence: dict[str, dict[str, float]] = {}
        counts = []
        for name in sequences:
            gt = read_posetrack_json(self.dataset.annotation_dir / f"{name}.json")
            pred = self.read(folder, name)
            try:
                seq_counts = evaluate_video(gt, pred, drop_last_frame=self.drop_last_frame)
            except ValueError as err:
                raise DataFormatError(Path(folder) / f"{name}.json", str(err)) from err
            counts.append(seq_counts)
            per_sequence[name] = summarise([seq_counts])
        combined = summarise(counts) if counts else {}
        return ScoreReport(BENCHMARK, per_sequence, combined,
                           scores={**per_sequence, COMBINED: combined})

    def sequence_events(self, folder: str | os.PathLike, sequence: str) -> EventRows:
        """Per-frame fn/fp/idsw events of the joints, as poseval matches them."""
        gt = read_posetrack_json(self.dataset.annotation_dir / f"{sequence}.json")
        return posetrack_sequence_events(sequence, gt, self.read(folder, sequence),
                                         drop_last_frame=self.drop_last_frame)
