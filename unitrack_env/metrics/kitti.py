"""KITTI tracking scores through TrackEval 1.3.0's ``Kitti2DBox``: per class and combined.

TrackEval's ``Kitti2DBox`` reads the label and result files and applies KITTI's preprocessing
(Van and Person_sitting are distractors, truncated or heavily occluded objects are ignored,
unmatched tracks inside DontCare regions or at most 25 pixels tall are removed); its metric
classes score each class, combine the sequences, and combine the classes as its Evaluator
does for datasets that combine classes (``cls_comb_cls_av``, ``cls_comb_det_av``).
"""

from __future__ import annotations

import io
import os
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from unitrack_env.errors import DataFormatError
from unitrack_env.metrics.motchallenge import (
    check_matrix_memory,
    flatten_results,
    trackeval_metrics,
    trackeval_sequence_data,
)

#: TrackEval's names of the evaluated classes.
CLASSES: tuple[str, ...] = ("car", "pedestrian")
#: TrackEval's names of the two class combinations.
CLASS_AVERAGE, DETECTION_AVERAGE = "cls_comb_cls_av", "cls_comb_det_av"
_TRACKER = "tracker"


def _layout(tmp: Path, label_dir: Path, results: Path, lengths: Mapping[str, int]) -> dict:
    """TrackEval's folder layout in ``tmp`` (links to the files) and its dataset config."""
    gt = tmp / "gt"
    (gt / "label_02").mkdir(parents=True)
    data = tmp / "trackers" / _TRACKER / "data"
    data.mkdir(parents=True)
    lines = []
    for seq, length in lengths.items():
        os.symlink((label_dir / f"{seq}.txt").resolve(), gt / "label_02" / f"{seq}.txt")
        os.symlink((results / f"{seq}.txt").resolve(), data / f"{seq}.txt")
        lines.append(f"{seq} empty 000000 {length:06d}\n")
    (gt / "evaluate_tracking.seqmap.training").write_text("".join(lines))
    return {"GT_FOLDER": str(gt), "TRACKERS_FOLDER": str(tmp / "trackers"),
            "OUTPUT_FOLDER": str(tmp / "out"), "TRACKERS_TO_EVAL": [_TRACKER],
            "CLASSES_TO_EVAL": list(CLASSES), "SPLIT_TO_EVAL": "training",
            "PRINT_CONFIG": False}


def kitti_raw_scores(label_dir: Path, results: Path,
                     lengths: Mapping[str, int]) -> dict[str, dict[str, dict[str, Any]]]:
    """TrackEval's raw results ``{sequence: {class: {metric: result}}}`` of ``results``.

    ``label_dir`` holds ``<seq>.txt`` ground truth, ``results`` the ``<seq>.txt`` result
    files, ``lengths`` each sequence's number of frames.
    """
    # lazy: optional dependency (trackeval, installed on its own with --no-deps)
    from trackeval.datasets import Kitti2DBox
    from trackeval.utils import TrackEvalException

    out: dict[str, dict[str, dict[str, Any]]] = {}
    with tempfile.TemporaryDirectory(prefix="unitrack-kitti-") as tmp:
        config = _layout(Path(tmp), label_dir, results, lengths)
        for seq in lengths:
            out[seq] = {}
            for cls in CLASSES:
                captured = io.StringIO()
                try:
                    data = trackeval_sequence_data(Kitti2DBox, config, _TRACKER, seq, cls,
                                                   captured)
                except TrackEvalException as exc:
                    raise DataFormatError(results / f"{seq}.txt",
                                          f"TrackEval rejected the data: {exc}") from exc
                check_matrix_memory(data, results / f"{seq}.txt", seq)
                out[seq][cls] = {m.get_name(): m.eval_sequence(data)
                                 for m in trackeval_metrics()}
    return out


def combine(raw: Mapping[str, Mapping[str, dict[str, Any]]],
            classes: Sequence[str] = CLASSES,
            super_categories: Mapping[str, Sequence[str]] | None = None,
            ) -> dict[str, dict[str, float]]:
    """Per class over the given sequences, and the class combinations, flattened.

    ``raw`` is :func:`kitti_raw_scores`' output (or a part of it, or another dataset's of the
    same shape) and ``classes`` its classes; the combinations are TrackEval's
    ``combine_classes_class_averaged`` and ``combine_classes_det_averaged``, and, for each
    ``super_categories`` entry (name: its classes), the detection average of its classes, as
    TrackEval's Evaluator does for datasets with super-categories (BDD100K).
    """
    groups = dict(super_categories or {})
    per_class: dict[str, dict[str, Any]] = {cls: {} for cls in classes}
    combos: dict[str, dict[str, Any]] = {CLASS_AVERAGE: {}, DETECTION_AVERAGE: {}}
    combos.update({name: {} for name in groups})
    for metric in trackeval_metrics():
        name = metric.get_name()
        for cls in classes:
            per_seq = {seq: raw[seq][cls][name] for seq in raw}
            per_class[cls][name] = metric.combine_sequences(per_seq)  # as the Evaluator
        by_class = {cls: per_class[cls][name] for cls in classes}
        combos[CLASS_AVERAGE][name] = metric.combine_classes_class_averaged(by_class)
        combos[DETECTION_AVERAGE][name] = metric.combine_classes_det_averaged(by_class)
        for group, members in groups.items():
            combos[group][name] = metric.combine_classes_det_averaged(
                {cls: by_class[cls] for cls in members})
    return {key: flatten_results(value) for key, value in {**per_class, **combos}.items()}
