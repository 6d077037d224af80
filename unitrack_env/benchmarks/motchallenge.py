"""MOTChallenge-layout benchmarks (MOT15/16/17/20, DanceTrack, SportsMOT): TrackEval's metrics."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from unitrack_env.benchmarks.base import (
    Benchmark,
    MissingResults,
    data_root,
    one_of,
    refuse_run_folder,
    rounded_digest,
)
from unitrack_env.benchmarks.kitti import flat_metrics
from unitrack_env.benchmarks.views import (
    ALL_LANES,
    LETTERBOX,
    ReportView,
    ScorecardColumn,
    association_head,
    iou_baseline,
)
from unitrack_env.datasets.mot_classes import ClassMap, class_map
from unitrack_env.datasets.mot_signatures import check_signature
from unitrack_env.datasets.motchallenge import (
    BENCHMARKS,
    MOTChallengeDataset,
    SequenceInfo,
    read_ground_truth,
    read_seqinfo,
)
from unitrack_env.datasets.synthetic.dance_sports import KIND as DANCE_SPORTS
from unitrack_env.io import atomic_write_text
from unitrack_env.metrics.events_mot import (
    EventRows,
    mot_sequence_events,
    preprocessed_frames,
    read_gt_rows,
)
from unitrack_env.metrics.kitti import combine
from unitrack_env.metrics.mot_classes import (
    check_class_rows,
    class_events,
    class_frames,
    class_raw_scores,
    merged_frames,
    read_class_results,
)
from unitrack_env.metrics.mot_results import read_result_file
from unitrack_env.metrics.mot_stats import mot_stats
from unitrack_env.metrics.motchallenge import score_folder, score_sequence
from unitrack_env.metrics.report import ScoreReport

if TYPE_CHECKING:
    from unitrack_env.metrics.mot_stats import MotStats

#: printf formats of the result columns (MOTChallenge files use 2 decimals; keep 3).
RESULT_FORMAT = ("%d", "%d", "%.3f", "%.3f", "%.3f", "%.3f", "%g", "%d", "%d", "%d")


def format_mot_results(rows: np.ndarray) -> str:
    """Format result rows ``frame, id, x, y, w, h, conf, -1, -1, -1`` as MOTChallenge text."""
    lines = [",".join(fmt % value for fmt, value in zip(RESULT_FORMAT, row, strict=True))
             for row in np.asarray(rows).reshape(-1, 10)]
    return "\n".join(lines) + ("\n" if lines else "")


def result_rows(frame: int, ids: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """One frame's tracks as result rows ``frame, id, x, y, w, h, 1, -1, -1, -1``."""
    rows = np.empty((len(ids), 10))
    rows[:, 0] = frame
    rows[:, 1] = ids
    rows[:, 2:6] = boxes
    rows[:, 6] = 1.0
    rows[:, 7:] = -1.0
    return rows


class MOTChallengeBenchmark(Benchmark):
    """MOTChallenge scoring under one rule set (``MOT15/16/17/20``, ``DanceTrack``, ``SportsMOT``).

    ``results`` of one sequence: the ``(k, 10)`` rows ``frame, id, x, y, w, h, conf, -1, -1,
    -1`` (see :func:`result_rows`), written as ``<folder>/<sequence>.txt``; on DanceTrack's
    test split as ``<folder>/tracker/<sequence>.txt``, the folder its server wants zipped
    (:meth:`~unitrack_env.datasets.mot_layouts.MOTLayout.result_dir`).
    """

    task = "mot"
    columns = ("HOTA", "IDF1", "MOTA", "IDSW", "DetA", "AssA", "MOTP", "CLR_FP", "CLR_FN",
               "MT", "ML")
    report_view = ReportView(lanes=ALL_LANES, thumbnails=True)
    intervals = "stats"  # CLEAR and identity sums per frame: metrics recomputed exactly
    scorecard = ScorecardColumn(
        "MOT", ("UniTrack/MOT16-v0", "UniTrack/MOT17-v0", "UniTrack/MOT20-v0",
                "UniTrack/MOT15-v0"),
        (association_head(("IDF1", "HOTA", "MOTA", "IDSW")),),
        iou_baseline(("IDF1", "HOTA", "MOTA", "IDSW")), ("UniTrack", "IDF1"),
        frozenset({"IDSW"}), order=3, input_size=LETTERBOX)

    def __init__(self, dataset: MOTChallengeDataset, *, synthetic: bool = False) -> None:
        super().__init__(dataset, synthetic=synthetic)
        #: The data's class map (None: the rule set's pedestrian scoring).
        self.class_map: ClassMap | None = dataset.class_map
        if self.class_map is not None:  # per class and combined, as KITTI's
            names = self.class_map.names
            self.columns = tuple(f"{prefix}{metric}" for metric in ("HOTA", "MOTA", "IDF1")
                                 for prefix in ("", *(f"{n}/" for n in names),
                                                "cls_comb_cls_av/")) + ("IDSW", "DetA", "AssA")

    @classmethod
    def build(cls, benchmark: str = "MOT17", root: str | os.PathLike | None = None,
              split: str = "train", detections: str | os.PathLike | None = "public",
              classes: dict[str, list[int]] | None = None, distractors: list[int] | None = None,
              ignore: list[int] | None = None) -> MOTChallengeBenchmark:
        """The benchmark of ``MOTChallengeEnv(benchmark=, root=, split=, detections=, ...)``.

        ``classes``, ``distractors``, ``ignore``: the class map
        (:mod:`unitrack_env.datasets.mot_classes`); without ``classes``, the map of
        ``<root>/classes.json`` if there is one, else pedestrians under the rule set.
        """
        one_of("benchmark", benchmark, sorted(BENCHMARKS))
        kind = DANCE_SPORTS if benchmark in DANCE_SPORTS.benchmarks else "motchallenge"
        path, synthetic = data_root(root, benchmark, benchmark, kind)
        cmap = class_map(path, classes, distractors, ignore)
        return cls(MOTChallengeDataset(path, benchmark, split, detections, cmap),
                   synthetic=synthetic)

    @property
    def name(self) -> str:
        """The rule set (``"MOT17"``, ...)."""
        return self.dataset.benchmark

    def _seqinfo(self, name: str) -> SequenceInfo:
        return read_seqinfo(self.dataset.split_dir / name, self.dataset.layout.frame_digits)

    def _results(self, folder: str | os.PathLike) -> Path:
        return self.dataset.layout.result_dir(Path(folder), self.dataset.split)

    def sequence_length(self, name: str) -> int:
        """Number of frames of ``name`` (reads only its seqinfo.ini)."""
        return self._seqinfo(name).length

    def has_ground_truth(self, name: str) -> bool:
        """Whether ``name`` has a ``gt/gt.txt``."""
        return self.dataset.has_ground_truth(name)

    def write(self, folder: str | os.PathLike, sequence: str, results: np.ndarray) -> None:
        """Write ``<folder>/<sequence>.txt`` in the official MOTChallenge result format."""
        atomic_write_text(self._results(folder) / f"{sequence}.txt", format_mot_results(results))

    def read(self, folder: str | os.PathLike, sequence: str) -> np.ndarray:
        """Read ``<folder>/<sequence>.txt`` as ``(k, c)`` float64 rows (checked classes)."""
        path = self._results(folder) / f"{sequence}.txt"
        if self.class_map is not None:
            return read_class_results(path, self.class_map, self.sequence_length(sequence))
        return read_result_file(path)

    def digest(self, results: np.ndarray) -> str:
        """SHA-256 of the rows rounded to 1e-3."""
        return rounded_digest(results)

    def score_sequence(self, sequence: str, results: np.ndarray) -> dict[str, float]:
        """TrackEval's metrics of one sequence's rows (it must have ground truth)."""
        if self.class_map is not None:
            path = Path(f"<results of {sequence}>")
            check_class_rows(results, self.class_map, self.sequence_length(sequence), path)
            return flat_metrics(combine({sequence: self._class_raw(sequence, results)},
                                        self.class_map.names))

        score = score_sequence(self.dataset.split_dir / sequence, results,
                               benchmark=self.name, seq_length=self.sequence_length(sequence))
        return dict(score.summary)

    def score_files(self, folder: str | os.PathLike, sequences: list[str]) -> ScoreReport:
        """Score ``<folder>/<sequence>.txt`` files with TrackEval (HOTA, CLEAR, Identity).

        With a class map: per class, per sequence and combined, and the class combinations
        (``<class>/HOTA``, ``cls_comb_cls_av/HOTA``; unprefixed: ``cls_comb_det_av``).
        """
        if self.class_map is not None:
            names = self.class_map.names
            raw = {seq: self._class_raw(seq, self.read(folder, seq)) for seq in sequences}
            combined = combine(raw, names)
            return ScoreReport(self.name, {seq: flat_metrics(combine({seq: raw[seq]}, names))
                                           for seq in sequences},
                               flat_metrics(combined), scores={"per_class": combined})
        return score_folder(self.dataset.split_dir, self._results(folder),
                            benchmark=self.name, sequences=sequences)

    def _class_gt(self, sequence: str) -> np.ndarray:
        """``gt.txt`` rows of ``sequence``, every class id checked against the class map."""
        seq_dir = self.dataset.split_dir / sequence
        read_ground_truth(seq_dir / "gt" / "gt.txt", self.name, self.sequence_length(sequence),
                          self.class_map)
        return read_gt_rows(seq_dir)

    def _class_raw(self, sequence: str, results: np.ndarray) -> dict:
        """TrackEval's raw per-class results of one sequence's checked rows."""
        return class_raw_scores(self._class_gt(sequence), results, self.class_map, sequence,
                                self.sequence_length(sequence))

    def _class_frames(self, folder: str | os.PathLike, sequence: str) -> dict:

        return class_frames(self._class_gt(sequence), self.read(folder, sequence),
                            self.class_map, self.sequence_length(sequence))

    def sequence_events(self, folder: str | os.PathLike, sequence: str) -> EventRows:
        """Per-frame tp/fn/fp/idsw/frag events of the official CLEAR matching.

        With a class map, each class's (its ``class`` column names it).
        """
        if self.class_map is not None:
            return class_events(sequence, self._class_frames(folder, sequence))
        return mot_sequence_events(sequence, read_gt_rows(self.dataset.split_dir / sequence),
                                   self.read(folder, sequence), self.sequence_length(sequence),
                                   self.name)

    def frame_stats(self, folder: str | os.PathLike, sequence: str,
                    cls: str | None = None) -> MotStats:
        """Per-frame CLEAR and identity statistics of the results in ``folder``.

        With a class map, of class ``cls``, or (None) of the classes together (their
        detection average).
        """
        if self.class_map is not None:
            frames = self._class_frames(folder, sequence)
            return mot_stats(merged_frames(frames) if cls is None else frames[cls])
        if cls is not None:
            raise ValueError(f"{self.name} scores no classes (asked for {cls!r})")
        return mot_stats(preprocessed_frames(read_gt_rows(self.dataset.split_dir / sequence),
                                             self.read(folder, sequence),
                                             self.sequence_length(sequence), self.name))

    def stat_classes(self) -> tuple[str, ...]:
        """The class map's classes (none without one)."""
        return self.class_map.names if self.class_map is not None else ()

    def frame_image(self, sequence: str, frame: int) -> Path:
        """``<sequence>/img1/<frame>.jpg`` (as its seqinfo.ini names it)."""
        return self._seqinfo(sequence).frame_path(frame)

    def frame_rate(self, sequence: str) -> float:
        """The seqinfo.ini's frame rate."""
        return float(self._seqinfo(sequence).frame_rate)


class DanceTrackBenchmark(MOTChallengeBenchmark):
    """DanceTrack, scored as every MOTChallenge-layout benchmark; its own scorecard column.

    DanceTrack's dancers look alike and move unpredictably: the appearance question of the
    UniTrack paper in its sharpest form. Its column, ``dancetrack``, is opt-in
    (``unitrack scorecard --tasks ...,dancetrack``): the default scorecard stays the paper's
    Table 2. It plays ``<data>/DanceTrack`` (val split) when ``--data`` has it, with
    detections from ``<data>/DanceTrack/detections/val/`` (DanceTrack ships none), else the
    embedded synthetic DanceTrack.
    """

    scorecard = ScorecardColumn(
        "DanceTrack", ("UniTrack/DanceTrack-v0",),
        (association_head(("IDF1", "HOTA", "MOTA", "IDSW")),),
        iou_baseline(("IDF1", "HOTA", "MOTA", "IDSW")), ("UniTrack", "IDF1"),
        frozenset({"IDSW"}), order=3.5, input_size=LETTERBOX, opt_in=True, task="dancetrack")


def score_split_folder(gt: str | os.PathLike, results: str | os.PathLike, benchmark: str,
                       sequences: list[str] | None = None, *,
                       allow_missing: bool = False) -> ScoreReport:
    """Score ``results/<seq>.txt`` against a split folder ``gt`` (``unitrack score --gt``).

    Every sequence of ``gt`` that has ``gt/gt.txt`` (or of ``sequences``) must have a result
    file, as in :meth:`~unitrack_env.benchmarks.base.Benchmark.score_folder`;
    a result file of a sequence without ground truth is refused.

    Raises:
        MissingResults: result files are missing (and ``allow_missing`` is False).
    """
    gt, results = Path(gt), Path(results)
    refuse_run_folder(results)
    split = (sorted(d.name for d in gt.iterdir() if (d / "gt" / "gt.txt").is_file())
             if gt.is_dir() else [])
    check_signature(benchmark, gt, split)  # another benchmark's data: refused, naming its id
    if not split or not results.is_dir():  # score_folder names what is wrong
        return score_folder(gt, results, benchmark=benchmark, sequences=sequences)
    extra = sorted(p.stem for p in results.glob("*.txt") if p.stem not in split)
    names = list(sequences or [*split, *extra])
    missing = [n for n in names if not (results / f"{n}.txt").is_file()]
    if missing and (not allow_missing or len(missing) == len(names)):
        raise MissingResults(results, missing, len(names), allow_missing)
    report = score_folder(gt, results, benchmark=benchmark,
                          sequences=[n for n in names if n not in missing])
    report.sequences_of, report.missing = len(set(split) | set(names)), missing
    return report
