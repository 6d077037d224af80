"""Per-frame error events of box and mask MOT, from the CLEAR matching the official score uses.

Each frame is preprocessed (:func:`~unitrack_env.metrics.mot_preprocess.preprocess`, or for
MOTS :func:`~unitrack_env.metrics.mots.mask_frame`) and matched by
:class:`~unitrack_env.metrics.clear_stream.StreamingClear`, whose pairs become the events
(types and columns: docs/report.md). Per sequence the ``tp``/``fp``/``fn``/``idsw``/``frag``
row counts equal TrackEval's ``CLR_TP``/``CLR_FP``/``CLR_FN``/``IDSW``/``Frag`` (tested on the
real fixtures): like ``Frag``, a gt id's first match is no fragmentation, and "not matched
before" looks only at frames with both ground truth and tracker boxes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from unitrack_env.datasets.mots_format import CLASS_IGNORE, MaskAnnotations
from unitrack_env.metrics.clear_stream import StreamingClear
from unitrack_env.metrics.mot_preprocess import (
    PreprocessedFrame,
    gt_frames_from_rows,
    preprocess,
    tracker_frames_from_rows,
)
from unitrack_env.metrics.mots import mask_frame

#: Columns of an event table, in order (every task uses the same columns; unused are NaN).
EVENT_COLUMNS: tuple[str, ...] = (
    "sequence", "frame", "type", "object", "gt_id", "track_id", "prev_track_id",
    "x", "y", "w", "h", "tx", "ty", "tw", "th", "iou", "center_error", "j", "f", "pck",
    "joint", "distance", "score", "track_iou",
)

#: Integer columns (nullable: NaN where a task leaves them empty).
ID_COLUMNS: tuple[str, ...] = ("object", "gt_id", "track_id", "prev_track_id", "joint")
#: Columns a table has only when some event names them, after :data:`EVENT_COLUMNS`
#: (``class``: the scored class of MOT data with a class map).
OPTIONAL_COLUMNS: tuple[str, ...] = ("class",)



@dataclass
class EventRows:
    """Columns of an event table being built (a dict of lists, one list per column)."""

    sequence: str
    columns: dict[str, list] = field(default_factory=lambda: {c: [] for c in EVENT_COLUMNS})

    def add(self, frame: int, kind: str, **values: float | str) -> None:
        """Append one event; columns not given are NaN."""
        unknown = set(values) - set(EVENT_COLUMNS) - set(OPTIONAL_COLUMNS)
        if unknown:
            raise ValueError(f"unknown event columns {sorted(unknown)}")
        for name in OPTIONAL_COLUMNS:  # the first event naming one: earlier ones get NaN
            if name in values and name not in self.columns:
                self.columns[name] = [np.nan] * len(self)
        self.columns["sequence"].append(self.sequence)
        self.columns["frame"].append(int(frame))
        self.columns["type"].append(kind)
        for name in (*EVENT_COLUMNS[3:], *(c for c in OPTIONAL_COLUMNS if c in self.columns)):
            self.columns[name].append(values.get(name, np.nan))

    def __len__(self) -> int:
        return len(self.columns["frame"])


def read_gt_rows(seq_dir: str | Path) -> np.ndarray:
    """``gt/gt.txt`` rows of a MOTChallenge sequence folder, columns by position."""
    path = Path(seq_dir) / "gt" / "gt.txt"
    rows = np.loadtxt(path, delimiter=",", ndmin=2, dtype=np.float64)
    return rows if rows.size else rows.reshape(0, 9)


def preprocessed_frames(gt_rows: np.ndarray, tracker_rows: np.ndarray, num_frames: int,
                        benchmark: str) -> list[PreprocessedFrame]:
    """Every frame of a sequence after MOTChallenge preprocessing (index ``t - 1`` = frame t)."""
    gts = gt_frames_from_rows(gt_rows, num_frames, benchmark=benchmark)
    trks = tracker_frames_from_rows(tracker_rows, num_frames)
    return [preprocess(g, t, benchmark) for g, t in zip(gts, trks, strict=True)]


def _box(values: np.ndarray, prefix: str = "") -> dict[str, float]:
    names = ("tx", "ty", "tw", "th") if prefix else ("x", "y", "w", "h")
    return {n: float(v) for n, v in zip(names, values, strict=True)}


def clear_events(sequence: str, frames: Sequence[PreprocessedFrame]) -> EventRows:
    """TP/FP/FN/IDSW/Frag events of one preprocessed sequence (see the module docstring)."""
    clear = StreamingClear()
    rows = EventRows(sequence)
    last: dict[int, int] = {}
    tracked_before: set[int] = set()  # gt ids matched at least once
    prev_step: set[int] = set()  # gt ids matched at the previous both-sided frame
    for t, fr in enumerate(frames, start=1):
        clear.update(fr.gt_ids, fr.gt_boxes, fr.tracker_ids, fr.tracker_boxes, iou=fr.iou)
        g_rows, t_cols = clear.last_match
        for r, c in zip(g_rows.tolist(), t_cols.tolist(), strict=True):
            g, k = int(fr.gt_ids[r]), int(fr.tracker_ids[c])
            common = {"gt_id": g, "track_id": k, "iou": float(fr.iou[r, c]),
                      **_box(fr.gt_boxes[r]), **_box(fr.tracker_boxes[c], "t")}
            rows.add(t, "tp", **common)
            if g in last and last[g] != k:
                rows.add(t, "idsw", prev_track_id=last[g], **common)
            if g in tracked_before and g not in prev_step:
                rows.add(t, "frag", **common)
            last[g] = k
            tracked_before.add(g)
        for r in np.setdiff1d(np.arange(len(fr.gt_ids)), g_rows).tolist():
            rows.add(t, "fn", gt_id=int(fr.gt_ids[r]), **_box(fr.gt_boxes[r]))
        for c in np.setdiff1d(np.arange(len(fr.tracker_ids)), t_cols).tolist():
            rows.add(t, "fp", track_id=int(fr.tracker_ids[c]), **_box(fr.tracker_boxes[c], "t"))
        if len(fr.gt_ids) and len(fr.tracker_ids):  # TrackEval's bookkeeping skips the rest
            prev_step = set(fr.gt_ids[g_rows].tolist())
    return rows


def mot_sequence_events(sequence: str, gt_rows: np.ndarray, tracker_rows: np.ndarray,
                        num_frames: int, benchmark: str) -> EventRows:
    """Events of one sequence from its ``gt.txt`` rows and result rows."""
    frames = preprocessed_frames(gt_rows, tracker_rows, num_frames, benchmark)
    return clear_events(sequence, frames)


def mots_sequence_events(sequence: str, gt: MaskAnnotations, results: MaskAnnotations, *,
                         first_frame: int, num_frames: int, class_id: int) -> EventRows:
    """Events of one MOTS sequence (``frame`` = 1-based position; KITTI files count from 0).

    Each frame is preprocessed by :func:`~unitrack_env.metrics.mots.mask_frame`, the step
    :class:`~unitrack_env.metrics.mots.MaskClearStream` (the environment's reward) uses
    before the same CLEAR matching; boxes are the masks' bounding boxes.
    """
    frames = []
    for t in range(first_frame, first_frame + num_frames):
        g, r = gt.rows(t), results.rows(t)
        cls = gt.classes[g]
        scored, ignore = g[cls == class_id], g[cls == CLASS_IGNORE]
        frames.append(mask_frame(gt.ids[scored], gt.rles(scored), gt.rles(ignore),
                                 results.ids[r], results.rles(r), boxes=True))
    return clear_events(sequence, frames)
