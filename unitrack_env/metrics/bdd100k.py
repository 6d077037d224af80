"""BDD100K box-tracking scores through TrackEval 1.3.0's ``BDD100K`` dataset class.

TrackEval's class reads its own JSON flavour (``index`` per frame, integer ids, a ``Crowd``
attribute); the Scalabel files BDD100K ships (``frameIndex``, string ids, ``crowd``) are
rewritten into it, box for box, and TrackEval does the rest: distractor categories (other
person, trailer, other vehicle) and crowd boxes of the ground truth become ignore regions,
unmatched result boxes more than half inside one are removed, each of the 8 classes is
scored alone. :func:`unitrack_env.metrics.kitti.combine` then combines sequences, classes
and super-categories as TrackEval's Evaluator does.
"""

from __future__ import annotations

import io
import json
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from unitrack_env.datasets.bdd100k import CLASSES, BDDLabel, read_bdd_frames
from unitrack_env.errors import DataFormatError
from unitrack_env.metrics.motchallenge import (
    check_matrix_memory,
    trackeval_metrics,
    trackeval_sequence_data,
)

_TRACKER = "tracker"


def trackeval_json(frames: list[list[BDDLabel]]) -> list[dict[str, Any]]:
    """Frames in TrackEval's BDD100K flavour; ids numbered from 0 in order of appearance."""
    numbers: dict[str, int] = {}
    out = []
    for index, labels in enumerate(frames):
        out.append({"index": index, "labels": [
            {"id": numbers.setdefault(label.ident, len(numbers)), "category": label.category,
             "box2d": dict(zip(("x1", "y1", "x2", "y2"), label.box, strict=True)),
             "score": label.score, "attributes": {"Crowd": label.crowd}}
            for label in labels]})
    return out


def bdd_raw_scores(ground_truth: Mapping[str, Path], results: Path,
                   ) -> dict[str, dict[str, dict[str, Any]]]:
    """TrackEval's raw results ``{sequence: {class: {metric: result}}}``.

    ``ground_truth`` maps each sequence to its JSON file, ``results`` is the folder of the
    ``<sequence>.json`` result files.
    """
    # lazy: optional dependency (trackeval, installed on its own with --no-deps)
    from trackeval.datasets import BDD100K
    from trackeval.utils import TrackEvalException

    out: dict[str, dict[str, dict[str, Any]]] = {}
    with tempfile.TemporaryDirectory(prefix="unitrack-bdd-") as tmp:
        gt, data = Path(tmp) / "gt", Path(tmp) / "trackers" / _TRACKER / "data"
        gt.mkdir()
        data.mkdir(parents=True)
        for seq, path in ground_truth.items():
            frames = read_bdd_frames(path)
            found = read_bdd_frames(results / f"{seq}.json", results=True, length=len(frames))
            (gt / f"{seq}.json").write_text(json.dumps(trackeval_json(frames)))
            (data / f"{seq}.json").write_text(json.dumps(trackeval_json(found)))
        config = {"GT_FOLDER": str(gt), "TRACKERS_FOLDER": str(Path(tmp) / "trackers"),
                  "OUTPUT_FOLDER": str(Path(tmp) / "out"), "TRACKERS_TO_EVAL": [_TRACKER],
                  "CLASSES_TO_EVAL": list(CLASSES), "PRINT_CONFIG": False}
        for seq in ground_truth:
            out[seq] = {}
            for cls in CLASSES:
                try:
                    seq_data = trackeval_sequence_data(BDD100K, config, _TRACKER, seq, cls,
                                                       io.StringIO())
                except TrackEvalException as exc:
                    raise DataFormatError(results / f"{seq}.json",
                                          f"TrackEval rejected the data: {exc}") from exc
                check_matrix_memory(seq_data, results / f"{seq}.json", seq)
                out[seq][cls] = {m.get_name(): m.eval_sequence(seq_data)
                                 for m in trackeval_metrics()}
    return out
