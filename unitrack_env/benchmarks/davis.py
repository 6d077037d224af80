"""The DAVIS-2017 semi-supervised benchmark: region J, boundary F and J&F."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np

from unitrack_env.benchmarks.base import Benchmark, data_root
from unitrack_env.benchmarks.views import Head, ReportView, ScorecardColumn
from unitrack_env.datasets.davis import (
    DAVISDataset,
    VOSSequence,
    read_label_png,
    write_davis_result,
)
from unitrack_env.errors import DataFormatError
from unitrack_env.metrics.events_mot import EventRows
from unitrack_env.metrics.report import COMBINED, ScoreReport
from unitrack_env.metrics.vos import (
    VOSScores,
    aggregate_vos,
    evaluate_vos_sequence,
    frame_scores,
)

if TYPE_CHECKING:
    import pandas as pd

_VOS_METRICS = ("J-Mean", "J&F-Mean", "F-Mean")

#: Folder of the DAVIS data under ``$UNITRACK_DATA``.
BENCHMARK_FOLDER = "DAVIS"
#: Name of the rule set in score reports.
BENCHMARK = "DAVIS-2017"


class DAVISBenchmark(Benchmark):
    """DAVIS-2017 semi-supervised scores (J, F, J&F: mean, recall, decay).

    ``results`` of one sequence: one ``(H, W)`` uint8 label map per frame, written as
    ``<folder>/<sequence>/<frame>.png`` palette PNGs (the official result format).
    """

    task = "vos"
    columns = ("J&F-Mean", "J-Mean", "F-Mean", "J-Recall", "F-Recall", "J-Decay", "F-Decay")
    report_view = ReportView(value=("j", "J"))
    intervals = "frames"  # J and F means are means over frames and objects
    frame_metrics = MappingProxyType({
        "J-Mean": lambda d: d["j"].to_numpy(), "F-Mean": lambda d: d["f"].to_numpy(),
        "J&F-Mean": lambda d: (d["j"].to_numpy() + d["f"].to_numpy()) / 2})
    scorecard = ScorecardColumn(
        "VOS", ("UniTrack/DAVIS-v0",), (Head("unitrack-vos", "UniTrack", _VOS_METRICS),),
        Head("repeat-mask", "repeat-mask", _VOS_METRICS, appearance=False),
        ("UniTrack", "J-Mean"), order=2, input_size=(1, 480, 854), head_seconds=0.6)

    @classmethod
    def build(cls, root: str | os.PathLike | None = None, split: str | None = "val",
              resolution: str = "480p", year: str = "2017") -> DAVISBenchmark:
        """The benchmark of ``DAVISEnv(root=, split=, resolution=, year=)``."""
        path, synthetic = data_root(root, BENCHMARK_FOLDER, BENCHMARK, "davis")
        return cls(DAVISDataset(path, split, resolution, year), synthetic=synthetic)

    @property
    def name(self) -> str:
        """``"DAVIS-2017"``."""
        return BENCHMARK

    def load(self, name: str) -> VOSSequence:
        """Sequence ``name`` of the data set (read once)."""
        return self._load_once(name, self.dataset.load)

    def sequence_length(self, name: str) -> int:
        """Number of frames (steps) of sequence ``name``."""
        return self.load(name).num_frames

    def has_ground_truth(self, name: str) -> bool:
        """Whether every frame of ``name`` is annotated (train/val, not test-dev)."""
        return self.load(name).has_ground_truth

    def write(self, folder: str | os.PathLike, sequence: str, results: list[np.ndarray]) -> None:
        """Write ``<folder>/<sequence>/<frame>.png`` palette PNGs, each atomically."""
        loaded = self.load(sequence)
        for t, labels in enumerate(results):
            write_davis_result(folder, loaded, t, labels)

    def read(self, folder: str | os.PathLike, sequence: str) -> list[np.ndarray]:
        """Read the label maps of every frame of ``sequence`` back (all must exist)."""
        loaded = self.load(sequence)
        return [self.read_frame(folder, loaded, t) for t in range(loaded.num_frames)]

    @staticmethod
    def read_frame(folder: str | os.PathLike, sequence: VOSSequence, t: int) -> np.ndarray:
        """Read frame ``t``'s result PNG; DataFormatError if missing, misfit or mislabelled."""
        path = Path(folder) / sequence.name / f"{sequence.frame_names[t]}.png"
        if not path.is_file():
            raise DataFormatError(path, f"result of sequence '{sequence.name}' frame "
                                  f"{sequence.frame_names[t]} not found")
        labels = read_label_png(path)
        expected = (sequence.image_size[1], sequence.image_size[0])
        if labels.shape != expected:
            raise DataFormatError(path, f"label map is {labels.shape[1]}x{labels.shape[0]}, the "
                                  f"frames are {expected[1]}x{expected[0]}")
        extra = sorted(set(np.unique(labels).tolist()) - {0, *sequence.object_ids})
        if extra:
            raise DataFormatError(path, f"labels {extra} are not objects of '{sequence.name}' "
                                  f"(objects: {list(sequence.object_ids)})")
        return labels

    def digest(self, results: list[np.ndarray]) -> str:
        """SHA-256 of the shapes and bytes of the label maps."""
        digest = hashlib.sha256()
        for labels in results:
            digest.update(np.asarray(labels.shape, dtype=np.int64).tobytes())
            digest.update(np.ascontiguousarray(labels).tobytes())
        return digest.hexdigest()

    def score_sequence(self, sequence: str, results: list[np.ndarray]) -> dict[str, float]:
        """The DAVIS summary of one sequence's label maps (first and last frame not scored)."""
        loaded = self.load(sequence)
        return dict(evaluate_vos_sequence(loaded.read_annotations(), list(results),
                                          loaded.object_ids, sequence_name=sequence).summary)

    def score_files(self, folder: str | os.PathLike, sequences: list[str]) -> ScoreReport:
        """Score ``<folder>/<seq>/<frame>.png`` results with the DAVIS-2017 protocol.

        Like the official evaluation, only the scored frames' PNGs (all but the first and
        the last) are read (see :meth:`read_frame` for the errors).
        """
        per_sequence: dict[str, dict[str, float]] = {}
        scores: dict[str, VOSScores] = {}
        for name in sequences:
            sequence = self.load(name)
            gt = sequence.read_annotations()
            predictions = [np.zeros_like(gt[0]) for _ in range(sequence.num_frames)]
            for t in range(1, sequence.num_frames - 1):
                predictions[t] = self.read_frame(folder, sequence, t)
            scores[name] = evaluate_vos_sequence(gt, predictions, sequence.object_ids,
                                                 sequence_name=name)
            per_sequence[name] = dict(scores[name].summary)
        combined: dict[str, float] = {}
        if scores:
            scores[COMBINED] = aggregate_vos(list(scores.values()))
            combined = dict(scores[COMBINED].summary)
        return ScoreReport(BENCHMARK, per_sequence, combined, scores)

    def sequence_events(self, folder: str | os.PathLike, sequence: str) -> EventRows:
        """One ``"frame"`` event per scored frame and object: its J and F."""
        seq = self.load(sequence)
        gt = seq.read_annotations()
        rows = EventRows(sequence)
        for t in range(1, seq.num_frames - 1):  # DAVIS scores all but the first and last frame
            j, f = frame_scores(gt[t], self.read_frame(folder, seq, t), seq.object_ids)
            for k, obj in enumerate(seq.object_ids):
                rows.add(t + 1, "frame", object=int(obj), j=float(j[k]), f=float(f[k]))
        return rows

    def combine_weights(self, events: pd.DataFrame, sequences: list[str]) -> dict[str, float]:
        """Each sequence's objects: DAVIS averages over the objects of all sequences."""
        objects = events.groupby("sequence")["object"].nunique()
        return {name: float(objects.get(name, 1)) for name in sequences}
