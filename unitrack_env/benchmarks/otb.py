"""The OTB-2015 benchmark: success AUC and precision at 20 pixels (the OTB toolkit's rules)."""

from __future__ import annotations

import importlib
import inspect
import os
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np

from unitrack_env.benchmarks.base import Benchmark, data_root, one_of, rounded_digest
from unitrack_env.benchmarks.sot_columns import LASOT_COLUMN, OTB_COLUMN
from unitrack_env.benchmarks.views import Attributes, Curve, ReportView
from unitrack_env.datasets.base import SequenceDataset
from unitrack_env.datasets.lasot import (
    GOT10K_SYNTHETIC,
    LASOT_SYNTHETIC,
    GOT10kDataset,
    LaSOTDataset,
)
from unitrack_env.datasets.nfs import NFS_SYNTHETIC, NfSDataset
from unitrack_env.datasets.otb import OTBDataset
from unitrack_env.datasets.sot import SOTSequence, read_box_file
from unitrack_env.datasets.sot_attributes import LASOT, OTB2015, UAV123, AttributeSource
from unitrack_env.datasets.synthetic.cache import SyntheticKind
from unitrack_env.datasets.trackingnet import TRACKINGNET_SYNTHETIC, TrackingNetDataset
from unitrack_env.datasets.uav123 import UAV123_SYNTHETIC, UAV123Dataset
from unitrack_env.errors import DataFormatError
from unitrack_env.io import atomic_write_text
from unitrack_env.metrics.events_mot import EventRows
from unitrack_env.metrics.report import COMBINED, ScoreReport
from unitrack_env.metrics.sot import (
    NORM_PRECISION_THRESHOLDS,
    OTB_CENTER_THRESHOLDS,
    OTB_OVERLAP_THRESHOLDS,
    PRECISION_THRESHOLD_PX,
    SOTScores,
    aggregate_sot,
    center_error_per_frame,
    evaluate_sot_sequence,
    overlap_per_frame,
    repair_predictions,
    valid_ground_truth,
)

if TYPE_CHECKING:
    import pandas as pd

#: Folder of the OTB data under ``$UNITRACK_DATA``.
BENCHMARK_FOLDER = "OTB"
#: Name of the rule set in score reports.
BENCHMARK = "OTB-2015"


@dataclass(frozen=True)
class SOTFormat:
    """A data format of single-object tracking: how to read it, where it is, what it is called.

    ``reader(root)`` lists and loads its sequences (a
    :class:`~unitrack_env.datasets.base.SequenceDataset` of
    :class:`~unitrack_env.datasets.sot.SOTSequence`); ``folder`` is its folder under
    ``$UNITRACK_DATA``; ``name`` the rule set score reports name. ``synthetic``: the
    format's own synthetic default in its layout (None: the task's, OTB layout, read with
    the OTB reader). ``absent_fails``: frames the reader flags ``absent`` are scored by the
    LaSOT toolkit's rule (removed, the rates still divided by every frame);
    ``normalized``: the scores add LaSOT's normalized precision (the benchmark is then a
    :class:`SOTProtocolBenchmark`, whose columns include it); ``benchmark``: ``"otb"`` (one
    of those two) or the ``"module:Class"`` of the format's own benchmark, a subclass of
    :class:`OTBBenchmark` (GOT-10k's protocol:
    :class:`unitrack_env.benchmarks.got10k.GOT10kBenchmark`; LaSOT's scorecard column:
    :class:`LaSOTBenchmark`); ``attributes``: where its sequences' attributes are (None: none).
    """

    reader: Callable[..., SequenceDataset[SOTSequence]]
    folder: str
    name: str
    synthetic: SyntheticKind | None = None
    absent_fails: bool = False
    normalized: bool = False
    benchmark: str = "otb"
    attributes: AttributeSource | None = None


def format_box_value(value: float) -> str:
    """A box number as its shortest float32 decimal (how OTB result files write it)."""
    return np.format_float_positional(np.float32(value), unique=True, trim="-")


def format_otb_results(boxes: np.ndarray) -> str:
    """Format ``(T, 4)`` boxes as an OTB result file: ``x,y,w,h`` per line, one per frame."""
    lines = [",".join(format_box_value(v) for v in row) for row in np.asarray(boxes).reshape(-1, 4)]
    return "\n".join(lines) + ("\n" if lines else "")


class OTBBenchmark(Benchmark):
    """OTB-2015 one-pass evaluation: success AUC, precision@20px, average overlap.

    ``results`` of one sequence: the ``(frames, 4)`` boxes ``x, y, w, h`` (the first frame
    included), written as ``<folder>/<sequence>.txt`` with one ``x,y,w,h`` line per frame.
    """

    task = "sot"
    columns = ("AUC", "Precision@20px", "AverageOverlap")
    report_view = ReportView(value=("iou", "IoU"))
    intervals = "frames"  # success AUC and precision are means over frames
    scorecard = OTB_COLUMN

    def __init__(self, dataset: SequenceDataset[SOTSequence], *, synthetic: bool = False,
                 rules: str = BENCHMARK, sot_format: SOTFormat | None = None) -> None:
        super().__init__(dataset, synthetic=synthetic)
        self.rules = rules
        self.sot_format = sot_format or SOTFormat(OTBDataset, BENCHMARK_FOLDER, rules)

    @classmethod
    def build(cls, root: str | os.PathLike | None = None, data_format: str = "otb",
              split: str | None = None, variant: str | None = None) -> OTBBenchmark:
        """The benchmark of ``OTBEnv(root=, data_format=, split=, variant=)``.

        ``data_format`` is a key of :data:`SOT_FORMATS`; ``split`` and ``variant`` go to
        its reader when given (a reader without them refuses them).
        """
        chosen = SOT_FORMATS[one_of("data_format", data_format, SOT_FORMATS)]
        options = {k: v for k, v in (("split", split), ("variant", variant)) if v is not None}
        unknown = set(options) - set(inspect.signature(chosen.reader).parameters)
        if unknown:
            names = " or ".join(repr(name) for name in sorted(unknown))
            raise ValueError(f"data_format {data_format!r} has no option {names}")
        kind = chosen.synthetic
        if kind is None:
            path, synthetic = data_root(root, chosen.folder, "OTB", "otb")
        else:
            path, synthetic = data_root(root, chosen.folder, kind.benchmarks[0], kind)
        reader = OTBDataset if synthetic and kind is None else chosen.reader
        klass = SOTProtocolBenchmark if chosen.normalized else OTBBenchmark
        if chosen.benchmark != "otb":  # its own module imports this one: looked up here
            module, _, name = chosen.benchmark.partition(":")
            klass = getattr(importlib.import_module(module), name)
        dataset = reader(path, **options) if reader is chosen.reader else reader(path)
        return klass(dataset, synthetic=synthetic, rules=chosen.name, sot_format=chosen)

    @property
    def name(self) -> str:
        """The format's rule set (``"OTB-2015"``)."""
        return self.rules

    def load(self, name: str) -> SOTSequence:
        """Read a sequence once (the reader's warning about trimmed copies appears once)."""
        return self._load_once(name, self._read_sequence)

    def _read_sequence(self, name: str) -> SOTSequence:
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            return self.dataset.load(name)

    def sequence_length(self, name: str) -> int:
        """Number of frames (steps) of sequence ``name`` (its ground-truth rows)."""
        return self.load(name).num_frames

    def has_ground_truth(self, name: str) -> bool:
        """Whether sequence ``name`` has boxes after the first frame."""
        return self.load(name).has_ground_truth

    def write(self, folder: str | os.PathLike, sequence: str, results: np.ndarray) -> None:
        """Write ``<folder>/<sequence>.txt``: one ``x,y,w,h`` line per frame, atomically."""
        atomic_write_text(Path(folder) / f"{sequence}.txt", format_otb_results(results))

    def read(self, folder: str | os.PathLike, sequence: str) -> np.ndarray:
        """Read ``<folder>/<sequence>.txt``; DataFormatError unless it has one box per frame."""
        loaded = self.load(self.dataset.resolve(sequence))
        path = Path(folder) / f"{loaded.name}.txt"
        if not path.is_file():
            raise DataFormatError(path, f"no result file for sequence '{loaded.name}'")
        boxes = read_box_file(path)
        if len(boxes) != loaded.num_frames:
            raise DataFormatError(
                path, f"has {len(boxes)} boxes but '{loaded.name}' has "
                f"{loaded.num_frames} frames (one line per frame, the first included)",
            )
        return boxes

    def digest(self, results: np.ndarray) -> str:
        """SHA-256 of the boxes rounded to 1e-3."""
        return rounded_digest(results)

    def _evaluate(self, sequence: SOTSequence, results: np.ndarray) -> SOTScores:
        """One sequence's scores by its format's rules (absent frames, normalized precision)."""
        rules = self.sot_format
        return evaluate_sot_sequence(results, sequence.boxes,
                                     absent=sequence.absent if rules.absent_fails else None,
                                     normalized=rules.normalized)

    def score_sequence(self, sequence: str, results: np.ndarray) -> dict[str, float]:
        """The metrics of one sequence's boxes."""
        return self._evaluate(self.load(sequence), results).as_dict()

    def score_files(self, folder: str | os.PathLike, sequences: list[str]) -> ScoreReport:
        """Score ``<folder>/<sequence>.txt`` result files with the OTB toolkit's rules."""
        per_sequence, scores = {}, {}
        for name in sequences:
            sequence = self.load(self.dataset.resolve(name))
            scores[sequence.name] = self._evaluate(sequence, self.read(folder, sequence.name))
            per_sequence[sequence.name] = scores[sequence.name].as_dict()
        combined: dict[str, float] = {}
        if scores:
            scores[COMBINED] = aggregate_sot(list(scores.values()))
            combined = scores[COMBINED].as_dict()
        return ScoreReport(self.name, per_sequence, combined, scores)

    def curves(self, folder: str | os.PathLike, sequences: list[str]) -> list[Curve]:
        """Success and precision plots (and normalized precision when the protocol has it).

        The curves of the combined row of :meth:`score_files`: its AUC and precision.
        """
        combined = self.score_files(folder, sequences).scores.get(COMBINED)
        if combined is None:
            return []
        plots = [Curve("Success plot", "Overlap threshold", tuple(OTB_OVERLAP_THRESHOLDS),
                       tuple(combined.success_curve), ("AUC", combined.auc)),
                 Curve("Precision plot", "Location error threshold (px)",
                       tuple(OTB_CENTER_THRESHOLDS), tuple(combined.precision_curve),
                       ("Precision@20px", combined.precision_20px))]
        if combined.norm_precision_curve is not None:
            plots.append(Curve("Normalized precision plot", "Normalized location error threshold",
                               tuple(NORM_PRECISION_THRESHOLDS),
                               tuple(combined.norm_precision_curve),
                               ("NormPrecision", float(combined.norm_precision or 0.0))))
        return plots

    def sequence_attributes(self, sequences: list[str]) -> Attributes | None:
        """The format's attributes of those ``sequences`` that have a record (None: none has).

        Reported per attribute: the result columns but the average overlap.
        """
        source = self.sot_format.attributes
        found = {} if source is None else {
            name: codes for name in sequences
            if (codes := source.read(self.dataset, self.dataset.resolve(name))) is not None}
        metrics = tuple(c for c in self.columns if c != "AverageOverlap")
        return Attributes(source.codes, source.names, found, metrics, source.source) \
            if source is not None and found else None

    def sequence_events(self, folder: str | os.PathLike, sequence: str) -> EventRows:
        """One ``"frame"`` event per frame: its IoU, centre error, true and tracked box."""
        gt = self.load(sequence).boxes
        pred = self._event_predictions(self.read(folder, sequence), gt)
        iou, err = overlap_per_frame(pred, gt), center_error_per_frame(pred, gt)
        rows = EventRows(sequence)
        for t in range(len(gt)):
            rows.add(t + 1, "frame", iou=float(iou[t]), center_error=float(err[t]),
                     **dict(zip(("x", "y", "w", "h"), map(float, gt[t]), strict=True)),
                     **dict(zip(("tx", "ty", "tw", "th"), map(float, pred[t]), strict=True)))
        return rows

    def _event_predictions(self, results: np.ndarray, gt: np.ndarray) -> np.ndarray:
        """The boxes the events record: the toolkit's repaired ones (as scored)."""
        return repair_predictions(results, gt, init_from_gt=True)

    @property
    def frame_metrics(self) -> Mapping[str, Callable[[pd.DataFrame], np.ndarray]]:
        """Per-frame AUC and Precision@20px of one sequence's ``"frame"`` events.

        Their means over frames are the official scores: a frame whose ground truth the
        toolkit deems invalid fails every overlap and passes every distance, an absent frame
        of the format's absent rule (LaSOT) fails both, as :func:`evaluate_sot_sequence` says.
        """
        return MappingProxyType({"AUC": self._frame_auc, "Precision@20px": self._frame_precision})

    def _frame_rules(self, d: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
        """``(absent, invalid)`` of each event row's frame, from the ground truth."""
        loaded = self.load(str(d["sequence"].iloc[0]))
        rows = d["frame"].to_numpy(int) - 1
        absent = (np.asarray(loaded.absent, bool)[rows] if self.sot_format.absent_fails
                  else np.zeros(len(rows), bool))
        return absent, ~valid_ground_truth(loaded.boxes)[rows]

    def _frame_auc(self, d: pd.DataFrame) -> np.ndarray:
        absent, invalid = self._frame_rules(d)
        hits = np.mean(d["iou"].to_numpy()[:, None] > OTB_OVERLAP_THRESHOLDS[None, :], axis=1)
        return np.where(absent | invalid, 0.0, hits)

    def _frame_precision(self, d: pd.DataFrame) -> np.ndarray:
        absent, invalid = self._frame_rules(d)
        hits = (d["center_error"] <= PRECISION_THRESHOLD_PX).to_numpy(float)
        return np.where(absent, 0.0, np.where(invalid, 1.0, hits))

    def combine_weights(self, events: pd.DataFrame, sequences: list[str]) -> dict[str, float]:
        """1 per sequence: OTB's combined scores are means of the sequences' scores."""
        return dict.fromkeys(sequences, 1.0)


class SOTProtocolBenchmark(OTBBenchmark):
    """A SOT benchmark whose protocol adds LaSOT's normalized precision (LaSOT, UAV123 here).

    Same files and rules as :class:`OTBBenchmark` plus the format's absent-frame rule;
    ``NormPrecision`` is the normalized precision plot at 0.2 (LaSOT toolkit's rank point).
    """

    columns = ("AUC", "Precision@20px", "NormPrecision", "AverageOverlap")


class LaSOTBenchmark(SOTProtocolBenchmark):
    """LaSOT: :class:`SOTProtocolBenchmark` with its own (opt-in) scorecard column."""

    scorecard = LASOT_COLUMN


#: The data formats :class:`OTBBenchmark` reads (its and ``OTBEnv``'s ``data_format=``). A new
#: format of the task is one row here (or added by a project at run time) beside its reader;
#: without ``root=`` and data it plays its own synthetic default, else the task's (OTB layout).
SOT_FORMATS: dict[str, SOTFormat] = {
    "otb": SOTFormat(OTBDataset, BENCHMARK_FOLDER, BENCHMARK, attributes=OTB2015),
    "lasot": SOTFormat(LaSOTDataset, "LaSOT", "LaSOT", LASOT_SYNTHETIC, absent_fails=True,
                       normalized=True, benchmark="unitrack_env.benchmarks.otb:LaSOTBenchmark",
                       attributes=LASOT),
    "uav123": SOTFormat(UAV123Dataset, "UAV123", "UAV123", UAV123_SYNTHETIC, normalized=True,
                        attributes=UAV123),
    "got10k": SOTFormat(GOT10kDataset, "GOT-10k", "GOT-10k", GOT10K_SYNTHETIC,
                        benchmark="unitrack_env.benchmarks.got10k:GOT10kBenchmark"),
    "trackingnet": SOTFormat(TrackingNetDataset, "TrackingNet", "TrackingNet",
                             TRACKINGNET_SYNTHETIC, normalized=True),
    "nfs": SOTFormat(NfSDataset, "NfS", "NfS", NFS_SYNTHETIC),
}


def rule_differences(bench: OTBBenchmark, folder: str | os.PathLike,
                     sequences: list[str]) -> dict[str, dict[str, float]]:
    """Score result files by the format's rules and with absent / invalid frames excluded.

    ``"excluded"`` leaves out, from numerator and denominator, every frame whose target is
    absent or whose ground truth is NaN or empty: the ``got10k`` package's UAV123 rule (its
    ``ExperimentUAV123._calc_metrics``), where LaSOT's and the OTB toolkit's count them as
    failures (success) or passes (precision, invalid OTB ground truth). Returns the combined
    scores of ``"default"``, ``"excluded"`` and their ``"difference"`` (default - excluded).
    """
    rules = bench.sot_format
    per_rule: dict[str, list[SOTScores]] = {"default": [], "excluded": []}
    for name in sequences:
        sequence = bench.load(bench.dataset.resolve(name))
        boxes = bench.read(folder, sequence.name)
        per_rule["default"].append(bench._evaluate(sequence, boxes))
        kept = ~np.asarray(sequence.absent, dtype=bool)
        kept[0] = True
        per_rule["excluded"].append(evaluate_sot_sequence(
            repair_predictions(boxes, sequence.boxes)[kept], sequence.boxes[kept],
            invalid_gt="exclude", normalized=rules.normalized))
    combined = {rule: aggregate_sot(scores).as_dict() for rule, scores in per_rule.items()}
    combined["difference"] = {k: combined["default"][k] - combined["excluded"][k]
                              for k in combined["default"]}
    return combined
