"""The MOTS benchmark (MOTS20, KITTI MOTS): TrackEval's HOTA, sMOTSA, Identity on masks."""

from __future__ import annotations

import os
from pathlib import Path

from unitrack_env.benchmarks.base import Benchmark, data_root, one_of, text_digest
from unitrack_env.benchmarks.views import (
    ALL_LANES,
    LETTERBOX,
    ReportView,
    ScorecardColumn,
    association_head,
    iou_baseline,
)
from unitrack_env.datasets.mots import BENCHMARKS, MOTSDataset
from unitrack_env.datasets.mots_format import (
    CLASS_IDS,
    MaskAnnotations,
    format_instances_txt,
    parse_instances_txt,
)
from unitrack_env.io import atomic_write_text
from unitrack_env.metrics.events_mot import EventRows, mots_sequence_events
from unitrack_env.metrics.mots import score_folder, score_sequence
from unitrack_env.metrics.report import ScoreReport

#: Default split of each benchmark.
DEFAULT_SPLITS = {"MOTS20": "train", "KITTI-MOTS": "training"}
#: Folder name under ``$UNITRACK_DATA`` of each benchmark.
DATA_FOLDERS = {"MOTS20": "MOTS20", "KITTI-MOTS": "KITTI-MOTS"}


class MOTSBenchmark(Benchmark):
    """MOTS scoring of one object class (``pedestrian`` on MOTS20; KITTI: also ``car``).

    ``results`` of one sequence: a :class:`~unitrack_env.datasets.mots.MaskAnnotations` of
    the reported masks with their ids, written as ``<folder>/<sequence>.txt`` (MOTS txt:
    ``time_frame id class_id img_height img_width rle``).
    """

    task = "mots"
    columns = ("HOTA", "sMOTSA", "IDF1", "IDSW", "DetA", "AssA", "MOTSA", "MOTSP", "CLR_FP",
               "CLR_FN")
    report_view = ReportView(lanes=ALL_LANES, unit="masks")
    no_intervals = "sMOTSA and HOTA of masks are not recomputed from per-frame statistics here"
    scorecard = ScorecardColumn(
        "MOTS", ("UniTrack/MOTS-v0",), (association_head(("IDF1", "HOTA", "sMOTSA")),),
        iou_baseline(("IDF1", "HOTA", "sMOTSA")), ("UniTrack", "IDF1"), order=4,
        input_size=LETTERBOX)

    def __init__(self, dataset: MOTSDataset, object_class: str = "pedestrian", *,
                 synthetic: bool = False) -> None:
        super().__init__(dataset, synthetic=synthetic)
        valid = ["pedestrian"] if dataset.benchmark == "MOTS20" else list(CLASS_IDS)
        if object_class not in valid:
            raise ValueError(f"object_class={object_class!r} is not a {dataset.benchmark} "
                             f"class; valid: {valid}")
        self.object_class = object_class

    @classmethod
    def build(cls, benchmark: str = "MOTS20", root: str | os.PathLike | None = None,
              split: str | None = None, detections: str | os.PathLike = "public",
              object_class: str = "pedestrian") -> MOTSBenchmark:
        """The benchmark of ``MOTSEnv(benchmark=, root=, split=, object_class=)``."""
        one_of("benchmark", benchmark, BENCHMARKS)
        path, synthetic = data_root(root, DATA_FOLDERS[benchmark], benchmark, kind="mots")
        dataset = MOTSDataset(path, benchmark, split or DEFAULT_SPLITS[benchmark], detections)
        return cls(dataset, object_class, synthetic=synthetic)

    @property
    def name(self) -> str:
        """``"MOTS20"`` or ``"KITTI-MOTS"``."""
        return self.dataset.benchmark

    def sequence_length(self, name: str) -> int:
        """Number of frames of sequence ``name``."""
        return self.dataset.info(name).length

    def has_ground_truth(self, name: str) -> bool:
        """Whether sequence ``name`` has ground truth."""
        return self.dataset.has_ground_truth(name)

    def write(self, folder: str | os.PathLike, sequence: str, results: MaskAnnotations) -> None:
        """Write ``<folder>/<sequence>.txt`` in the official MOTS txt result format."""
        atomic_write_text(Path(folder) / f"{sequence}.txt", format_instances_txt(results))

    def read(self, folder: str | os.PathLike, sequence: str) -> MaskAnnotations:
        """Read ``<folder>/<sequence>.txt`` (MOTS txt)."""
        return parse_instances_txt(Path(folder) / f"{sequence}.txt")

    def digest(self, results: MaskAnnotations) -> str:
        """SHA-256 of the MOTS result text."""
        return text_digest(format_instances_txt(results))

    def score_sequence(self, sequence: str, results: MaskAnnotations) -> dict[str, float]:
        """TrackEval's MOTS metrics of one sequence's masks (it must have ground truth)."""
        gt = self.dataset.ground_truth(sequence)
        if gt is None:
            raise ValueError("this sequence has no ground truth to score against")
        score = score_sequence(gt, results, seq_length=self.sequence_length(sequence),
                               benchmark=self.name, object_class=self.object_class,
                               sequence=sequence)
        return dict(score.summary)

    def score_files(self, folder: str | os.PathLike, sequences: list[str]) -> ScoreReport:
        """Score ``<folder>/<sequence>.txt`` files with TrackEval (HOTA, CLEAR, Identity)."""
        return score_folder(self.dataset, folder, sequences, object_class=self.object_class)

    def sequence_events(self, folder: str | os.PathLike, sequence: str) -> EventRows:
        """Per-frame tp/fn/fp/idsw/frag events of the official mask matching."""
        info = self.dataset.info(sequence)
        return mots_sequence_events(sequence, self.dataset.ground_truth(sequence),
                                    self.read(folder, sequence), first_frame=info.first_frame,
                                    num_frames=info.length,
                                    class_id=CLASS_IDS[self.object_class])
