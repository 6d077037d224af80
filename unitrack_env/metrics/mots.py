"""Official MOTS scores through TrackEval 1.3.0, and per-frame mask CLEAR counts.

TrackEval's ``MOTSChallenge`` (MOTS20) / ``KittiMOTS`` data set classes with HOTA, CLEAR (on
masks its ``MOTA``/``MOTP``/``sMOTA`` are MOTSA, MOTSP, sMOTSA, Voigtlaender et al. CVPR 2019;
both names are returned), Identity and Count, called as
:mod:`unitrack_env.metrics.motchallenge` calls them (never the ``Evaluator``), track ids
relabelled to ``1..K`` for the same reason. ``time_frame`` uses the benchmark's numbering
(MOTS20 1-based, KITTI 0-based); masks of one frame must not overlap. :class:`MaskClearStream`
(the environment's reward) is TrackEval's MOTS preprocessing of one frame followed by
:class:`~unitrack_env.metrics.clear_stream.StreamingClear`; summed over a sequence,
``(tp - fp - idsw) / (tp + fn)`` is TrackEval's MOTSA.
"""

from __future__ import annotations

import io
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from unitrack_env.datasets.mots_format import (
    CLASS_IDS,
    MaskAnnotations,
    format_instances_txt,
    parse_instances_txt,
)
from unitrack_env.datasets.rle import mask_api as mask_utils
from unitrack_env.datasets.rle import quiet_pycocotools
from unitrack_env.errors import DataFormatError
from unitrack_env.metrics.clear_stream import FrameClear, StreamingClear
from unitrack_env.metrics.mot_preprocess import PreprocessedFrame
from unitrack_env.metrics.motchallenge import (
    SequenceScore,
    check_matrix_memory,
    flatten_results,
    trackeval_metrics,
    trackeval_sequence_data,
)
from unitrack_env.metrics.report import COMBINED, ScoreReport

#: TrackEval data set class of each benchmark.
TRACKEVAL_DATASETS = {"MOTS20": "MOTSChallenge", "KITTI-MOTS": "KittiMOTS"}
#: Minimum mask IoU of a match (TrackEval's CLEAR threshold and MOTS preprocessing).
MATCH_IOU = 0.5
#: Unmatched tracker masks with more than this fraction inside an ignore region are dropped.
IGNORE_IOA = 0.5
#: TrackEval's comparison slack.
EPS = float(np.finfo(float).eps)
#: Alias -> TrackEval CLEAR field on masks.
MOTS_ALIASES = {"MOTSA": "MOTA", "MOTSP": "MOTP", "sMOTSA": "sMOTA"}
_TRACKER = "tracker"
_SUB = "data"


def _flatten(raw: dict[str, dict[str, Any]]) -> dict[str, float]:
    """TrackEval's flat summary plus the MOTS names of the CLEAR fields on masks."""
    out = flatten_results(raw)
    for alias, name in MOTS_ALIASES.items():
        if name in out:
            out[alias] = out[name]
    return out


def _as_annotations(value: MaskAnnotations | str | Path) -> MaskAnnotations:
    if isinstance(value, MaskAnnotations):
        return value
    return parse_instances_txt(value)


def _relabelled(results: MaskAnnotations, class_id: int) -> MaskAnnotations:
    ids = np.unique(results.ids, return_inverse=True)[1].astype(np.int64) + 1 \
        if len(results) else results.ids
    return MaskAnnotations(results.frames, ids, np.full(len(results), class_id, np.int64),
                           results.heights, results.widths, results.counts, results.scores,
                           results.lines, results.source)


def score_sequence(
    ground_truth: MaskAnnotations | str | Path,
    results: MaskAnnotations | str | Path,
    *,
    seq_length: int,
    benchmark: str = "MOTS20",
    object_class: str = "pedestrian",
    sequence: str = "sequence",
) -> SequenceScore:
    """Score one sequence's results with TrackEval (HOTA, CLEAR, Identity, Count).

    Both sides are records or MOTS txt files; every result row is taken as ``object_class``
    (``"car"`` only on KITTI-MOTS, whose frames are 0-based). Data TrackEval rejects raises
    DataFormatError naming the result file.
    """
    if benchmark not in TRACKEVAL_DATASETS:
        raise ValueError(f"unknown MOTS benchmark {benchmark!r}; valid: {list(TRACKEVAL_DATASETS)}")
    if object_class not in CLASS_IDS or (benchmark == "MOTS20" and object_class != "pedestrian"):
        raise ValueError(f"object_class {object_class!r} is not evaluated on {benchmark}")
    gt = _as_annotations(ground_truth)
    res = _relabelled(_as_annotations(results), CLASS_IDS[object_class])
    source = res.source or Path(f"<results of {sequence}>")
    raw = _run_trackeval(gt, res, benchmark, object_class, int(seq_length), source)
    return SequenceScore(sequence=sequence, benchmark=benchmark, summary=_flatten(raw), raw=raw)


def _run_trackeval(gt: MaskAnnotations, res: MaskAnnotations, benchmark: str, cls: str,
                   seq_length: int, source: Path) -> dict[str, dict[str, Any]]:
    # lazy: optional dependency (trackeval, installed on its own with --no-deps)
    import trackeval.datasets as te_datasets
    from trackeval.utils import TrackEvalException

    seq = "seq"
    with tempfile.TemporaryDirectory(prefix="unitrack-mots-") as tmp:
        gt_file = Path(tmp) / "gt" / f"{seq}.txt"
        gt_file.parent.mkdir()
        gt_file.write_text(format_instances_txt(gt), encoding="ascii")
        data_dir = Path(tmp) / _TRACKER / _SUB
        data_dir.mkdir(parents=True)
        (data_dir / f"{seq}.txt").write_text(format_instances_txt(res), encoding="ascii")
        config: dict[str, Any] = {
            "GT_FOLDER": str(Path(tmp) / "gt"),
            "TRACKERS_FOLDER": tmp,
            "OUTPUT_FOLDER": tmp,
            "TRACKERS_TO_EVAL": [_TRACKER],
            "CLASSES_TO_EVAL": [cls],
            "INPUT_AS_ZIP": False,
            "PRINT_CONFIG": False,
            "TRACKER_SUB_FOLDER": _SUB,
            "OUTPUT_SUB_FOLDER": "",
            "SEQ_INFO": {seq: seq_length},
            "GT_LOC_FORMAT": "{gt_folder}/{seq}.txt",
        }
        if benchmark == "MOTS20":
            config["SKIP_SPLIT_FOL"] = True
        dataset_class = getattr(te_datasets, TRACKEVAL_DATASETS[benchmark])
        captured = io.StringIO()
        try:
            with quiet_pycocotools():  # TrackEval decodes the masks with pycocotools
                data = trackeval_sequence_data(dataset_class, config, _TRACKER, seq, cls,
                                               captured)
        except TrackEvalException as exc:
            raise DataFormatError(source, f"TrackEval rejected the data: {exc}") from exc
        check_matrix_memory(data, source, seq)
        with quiet_pycocotools():
            return {metric.get_name(): metric.eval_sequence(data)
                    for metric in trackeval_metrics()}


def combine_sequence_scores(scores: Mapping[str, SequenceScore]) -> SequenceScore:
    """Combine per-sequence results as each TrackEval metric's ``combine_sequences`` does."""
    if not scores:
        raise ValueError("no sequence scores to combine")
    raw = {
        metric.get_name(): metric.combine_sequences(
            {seq: s.raw[metric.get_name()] for seq, s in scores.items()})
        for metric in trackeval_metrics()
    }
    benchmark = next(iter(scores.values())).benchmark
    return SequenceScore(sequence=COMBINED, benchmark=benchmark, summary=_flatten(raw), raw=raw)


def score_folder(
    dataset: Any, results_dir: str | Path, sequences: Sequence[str], *,
    object_class: str = "pedestrian",
) -> ScoreReport:
    """Score ``<results_dir>/<seq>.txt`` (MOTS txt) against a :class:`MOTSDataset`'s gt.

    A missing file or a malformed line raises DataFormatError naming file, line and field.
    """
    results_dir = Path(results_dir)
    scores: dict[str, SequenceScore] = {}
    for seq in dict.fromkeys(sequences):
        path = results_dir / f"{seq}.txt"
        if not path.is_file():
            raise DataFormatError(path, f"result file for sequence '{seq}' is missing")
        gt = dataset.ground_truth(seq)
        if gt is None:
            raise DataFormatError(path, f"sequence '{seq}' has no ground truth")
        scores[seq] = score_sequence(gt, path, seq_length=dataset.info(seq).length,
                                     benchmark=dataset.benchmark, object_class=object_class,
                                     sequence=seq)
    if not scores:
        raise ValueError("no sequences to score")
    combined = combine_sequence_scores(scores)
    return ScoreReport(
        benchmark=dataset.benchmark,
        per_sequence={seq: dict(s.summary) for seq, s in scores.items()},
        combined=dict(combined.summary),
        scores={**scores, COMBINED: combined},
    )


# ------------------------------------------------------------------ per-frame counts
def mask_iou(rles_a: list[dict], rles_b: list[dict], *, ioa: bool = False) -> np.ndarray:
    """``(len(a), len(b))`` mask IoU of pycocotools RLEs (``ioa``: intersection / area of a)."""
    if not rles_a or not rles_b:
        return np.zeros((len(rles_a), len(rles_b)))
    # pycocotools' "crowd" flag on the second argument divides by the first one's area.
    crowd = [bool(ioa)] * len(rles_b)
    return np.asarray(mask_utils.iou(rles_a, rles_b, crowd), dtype=np.float64).reshape(
        len(rles_a), len(rles_b))


@dataclass
class MaskClearStream:
    """TrackEval's MOTS preprocessing and CLEAR matching, one frame at a time.

    All state is on the instance; :meth:`reset` starts a new sequence.
    """

    threshold: float = MATCH_IOU
    _clear: StreamingClear = field(default_factory=StreamingClear, init=False, repr=False)

    def reset(self) -> None:
        """Forget all matches and totals."""
        self._clear = StreamingClear(threshold=self.threshold)

    @property
    def totals(self) -> Any:
        """Running :class:`~unitrack_env.metrics.clear_stream.ClearTotals`."""
        return self._clear.totals

    def update(self, gt_ids: np.ndarray, gt_rles: list[dict], ignore_rles: list[dict],
               tracker_ids: np.ndarray, tracker_rles: list[dict]) -> FrameClear:
        """Score one frame: gt masks of the evaluated class, ignore regions, tracker masks."""
        fr = mask_frame(gt_ids, gt_rles, ignore_rles, tracker_ids, tracker_rles)
        return self._clear.update(fr.gt_ids, fr.gt_boxes, fr.tracker_ids, fr.tracker_boxes,
                                  iou=fr.iou)


def mask_frame(gt_ids: np.ndarray, gt_rles: list[dict], ignore_rles: list[dict],
               tracker_ids: np.ndarray, tracker_rles: list[dict], *,
               boxes: bool = False) -> PreprocessedFrame:
    """TrackEval's MOTS preprocessing of one frame, ready for the CLEAR matching.

    Unmatched tracker masks mostly inside the merged ignore region are dropped
    (``tracker_kept``). Boxes are the masks' bounding boxes when ``boxes`` (for drawing
    error events), else zeros (the matching uses only ``iou``).
    """
    gt_ids = np.asarray(gt_ids, dtype=np.int64).reshape(-1)
    tracker_ids = np.asarray(tracker_ids, dtype=np.int64).reshape(-1)
    sim = mask_iou(gt_rles, tracker_rles)
    unmatched = np.ones(len(tracker_ids), dtype=bool)
    if len(gt_ids) and len(tracker_ids):
        score = sim.copy()
        score[score < MATCH_IOU - EPS] = -10000.0
        rows, cols = linear_sum_assignment(-score)
        unmatched[cols[score[rows, cols] > EPS]] = False
    keep = np.ones(len(tracker_ids), dtype=bool)
    if ignore_rles and unmatched.any():
        region = mask_utils.merge(ignore_rles, intersect=False)
        idx = np.flatnonzero(unmatched)
        inside = mask_iou([tracker_rles[i] for i in idx], [region], ioa=True)[:, 0]
        keep[idx[inside > IGNORE_IOA + EPS]] = False
    return PreprocessedFrame(
        gt_ids, _rle_boxes(gt_rles, boxes), tracker_ids[keep],
        _rle_boxes([r for r, k in zip(tracker_rles, keep, strict=True) if k], boxes),
        sim[:, keep], np.ones(len(gt_ids), dtype=bool), keep)


def _rle_boxes(rles: list[dict], boxes: bool) -> np.ndarray:
    if not boxes or not rles:
        return np.zeros((len(rles), 4))

    return np.asarray(mask_utils.toBbox(rles), dtype=np.float64).reshape(len(rles), 4)
