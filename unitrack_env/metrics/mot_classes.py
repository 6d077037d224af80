"""Per-class MOT scores of MOTChallenge-layout data with a class map, through TrackEval.

Each class of a :class:`~unitrack_env.datasets.mot_classes.ClassMap` is scored as TrackEval's
``MotChallenge2DBox`` scores pedestrians, on that class's view of the data
(:meth:`ClassMap.pedestrian_rows`: its ground truth as pedestrians, the distractors as
distractors, its tracks); the classes are then combined as TrackEval's Evaluator combines
them (:func:`unitrack_env.metrics.kitti.combine`). The per-frame forms (events, statistics,
the environment's reward) preprocess the same views with
:func:`unitrack_env.metrics.mot_preprocess.preprocess_frame`.
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from unitrack_env.datasets.mot_classes import VIEW_BENCHMARK, ClassMap
from unitrack_env.errors import DataFormatError
from unitrack_env.metrics.events_mot import EventRows, clear_events, preprocessed_frames
from unitrack_env.metrics.mot_preprocess import PreprocessedFrame, preprocess_frame
from unitrack_env.metrics.mot_results import parse_result_file, validate_tracker_rows
from unitrack_env.metrics.motchallenge import score_sequence

#: Column of a result row that holds its class id (MOTChallenge's 8th column).
CLASS_COLUMN = 7


def read_class_results(path: Path, class_map: ClassMap, seq_length: int) -> np.ndarray:
    """A result file's rows, each carrying a class id the map names in column 8.

    Rows of distractor or ignored ids are kept (no class scores them); a row without a
    class column, or of an id the map does not name (e.g. -1), is refused with its line.
    """
    rows, lines = parse_result_file(path)
    check_class_rows(rows, class_map, seq_length, path, lines)
    return rows


def check_class_rows(rows: np.ndarray, class_map: ClassMap, seq_length: int,
                     source: Path, lines: np.ndarray | None = None) -> None:
    """Refuse result rows without a known class, and what TrackEval refuses in any row."""
    rows = np.asarray(rows, dtype=np.float64)
    if len(rows) and rows.shape[1] <= CLASS_COLUMN:
        raise DataFormatError(source, f"{rows.shape[1]} columns; with a class map each result "
                              "row carries its class id in column 8 (frame, id, x, y, w, h, "
                              "conf, class, -1, -1)", line=int(lines[0]) if lines is not None
                              else None, field="class")
    if len(rows):
        class_map.check_column(source, rows[:, CLASS_COLUMN],
                               lines if lines is not None else np.arange(1, len(rows) + 1),
                               what="result")
        unclassed = rows.copy()
        unclassed[:, CLASS_COLUMN] = -1  # the class is checked above; the rest as TrackEval
        validate_tracker_rows(unclassed, seq_length, source, lines)


def class_raw_scores(gt_rows: np.ndarray, tracks: np.ndarray, class_map: ClassMap,
                     sequence: str, seq_length: int) -> dict[str, dict[str, Any]]:
    """TrackEval's raw results ``{class: {metric: result}}`` of one sequence.

    ``gt_rows`` are its ``gt.txt`` rows, ``tracks`` its checked result rows
    (:func:`check_class_rows`).
    """
    out = {}
    with tempfile.TemporaryDirectory(prefix="unitrack-mot-classes-") as tmp:
        for name in class_map.names:
            gt, mine = class_map.pedestrian_rows(name, gt_rows, tracks)
            seq_dir = Path(tmp) / name / sequence
            (seq_dir / "gt").mkdir(parents=True)
            np.savetxt(seq_dir / "gt" / "gt.txt", gt, fmt="%.17g", delimiter=",")
            out[name] = score_sequence(seq_dir, mine, benchmark=VIEW_BENCHMARK,
                                       seq_length=seq_length).raw
    return out


def class_frames(gt_rows: np.ndarray, tracks: np.ndarray, class_map: ClassMap,
                 num_frames: int) -> dict[str, list[PreprocessedFrame]]:
    """Every frame of one sequence per class, after its view's MOTChallenge preprocessing."""
    out = {}
    for name in class_map.names:
        gt, mine = class_map.pedestrian_rows(name, gt_rows, tracks)
        out[name] = preprocessed_frames(gt, mine, num_frames, VIEW_BENCHMARK)
    return out


def merge_classes(frames: Sequence[PreprocessedFrame]) -> PreprocessedFrame:
    """The classes' frames of one time step as one frame (detection-averaged statistics).

    Ids are made distinct per class (id ``i`` of class ``k`` of ``n`` becomes ``i * n + k``,
    one to one for every id) and the IoU between classes is 0, so CLEAR, identity and HOTA
    matchings stay within each class.
    """
    n = len(frames)
    gt_ids = np.concatenate([f.gt_ids * n + k for k, f in enumerate(frames)])
    trk_ids = np.concatenate([f.tracker_ids * n + k for k, f in enumerate(frames)])
    iou = np.zeros((len(gt_ids), len(trk_ids)))
    r = c = 0
    for f in frames:
        iou[r:r + len(f.gt_ids), c:c + len(f.tracker_ids)] = f.iou
        r, c = r + len(f.gt_ids), c + len(f.tracker_ids)
    return PreprocessedFrame(
        gt_ids=gt_ids.astype(np.int64), gt_boxes=np.concatenate([f.gt_boxes for f in frames]),
        tracker_ids=trk_ids.astype(np.int64),
        tracker_boxes=np.concatenate([f.tracker_boxes for f in frames]), iou=iou,
        gt_kept=np.concatenate([f.gt_kept for f in frames]),
        tracker_kept=np.concatenate([f.tracker_kept for f in frames]))


def class_frame(class_map: ClassMap, frame: int, gt_ids: np.ndarray, gt_boxes: np.ndarray,
                flags: np.ndarray, gt_classes: np.ndarray, tracks: np.ndarray,
                ) -> PreprocessedFrame:
    """One frame's classes preprocessed and merged (the environment's per-step score).

    ``tracks`` are the frame's result rows (class id in column 8).
    """
    gt = np.column_stack([np.full(len(gt_ids), frame), gt_ids, gt_boxes, flags, gt_classes])
    parts = []
    for name in class_map.names:
        view, mine = class_map.pedestrian_rows(name, gt.reshape(-1, 8), tracks)
        parts.append(preprocess_frame(view[:, 1], view[:, 2:6], view[:, 7],
                                      view[:, 6].astype(np.int64), mine[:, 1], mine[:, 2:6],
                                      VIEW_BENCHMARK))
    return merge_classes(parts)


def merged_frames(per_class: Mapping[str, list[PreprocessedFrame]]) -> list[PreprocessedFrame]:
    """Each time step's classes merged by :func:`merge_classes`."""
    return [merge_classes(step) for step in zip(*per_class.values(), strict=True)]


def class_events(sequence: str, per_class: Mapping[str, list[PreprocessedFrame]]) -> EventRows:
    """The CLEAR events of every class (each event's ``class`` column names it), by frame."""
    rows = EventRows(sequence)
    parts = [(name, clear_events(sequence, frames)) for name, frames in per_class.items()]
    order = sorted(((frame, k, i) for k, (_, part) in enumerate(parts)
                    for i, frame in enumerate(part.columns["frame"])))
    for frame, k, i in order:
        name, part = parts[k]
        values = {col: part.columns[col][i] for col in part.columns
                  if col not in ("sequence", "frame", "type")}
        rows.add(frame, part.columns["type"][i], **values, **{"class": name})
    return rows
