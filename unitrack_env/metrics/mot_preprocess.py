"""MOTChallenge per-frame preprocessing, exactly as the official evaluation does it.

Our numpy restatement, per frame so that an environment can score every step, of TrackEval
1.3.0's ``MotChallenge2DBox.get_preprocessed_seq_data`` (J. Luiten et al.,
``trackeval/datasets/mot_challenge_2d_box.py``); the rules are listed in docs/evaluation.md
("Which rules are applied"). Surviving rows keep their input order: it matters only for
Hungarian tie-breaking, and keeping it makes our sums equal TrackEval's to the last count.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from unitrack_env.geometry import box_iou

#: MOTChallenge class ids of ``gt.txt`` column 8 (MOT16/17/20), as TrackEval names them.
MOT_CLASS_IDS: dict[str, int] = {
    "pedestrian": 1,
    "person_on_vehicle": 2,
    "car": 3,
    "bicycle": 4,
    "motorbike": 5,
    "non_mot_vehicle": 6,
    "static_person": 7,
    "distractor": 8,
    "occluder": 9,
    "occluder_on_ground": 10,
    "occluder_full": 11,
    "reflection": 12,
    "crowd": 13,
}

PEDESTRIAN_CLASS: int = MOT_CLASS_IDS["pedestrian"]  # the only class that is evaluated
#: Classes whose matched tracker boxes are removed (MOT16, MOT17; MOT20 adds non-MOT vehicles).
DISTRACTOR_CLASSES: tuple[int, ...] = tuple(
    MOT_CLASS_IDS[name]
    for name in ("person_on_vehicle", "static_person", "distractor", "reflection")
)
MOT20_DISTRACTOR_CLASSES: tuple[int, ...] = (*DISTRACTOR_CLASSES, MOT_CLASS_IDS["non_mot_vehicle"])
#: TrackEval's BENCHMARK values: DanceTrack and SportsMOT are scored by TrackEval's
#: MotChallenge2DBox under their own names, which it treats as MOT17 (class columns read,
#: MOT16/17 distractors removed), as their official kits run it.
BENCHMARKS: tuple[str, ...] = ("MOT15", "MOT16", "MOT17", "MOT20", "DanceTrack", "SportsMOT")
CLASSLESS_BENCHMARK: str = "MOT15"  # no class column, no distractor removal
MATCH_IOU_THRESHOLD: float = 0.5  # to match a tracker box (preprocessing and CLEAR)
EPS: float = float(np.finfo(float).eps)  # TrackEval's tolerance on every threshold


def normalize_benchmark(benchmark: str) -> str:
    """Return the canonical benchmark name (``"MOT17"``) or raise naming the valid ones.

    >>> normalize_benchmark("mot17")
    'MOT17'
    """
    name = {b.upper(): b for b in BENCHMARKS}.get(str(benchmark).strip().upper())
    if name is None:
        raise ValueError(
            f"unknown MOTChallenge benchmark {benchmark!r}; expected one of {', '.join(BENCHMARKS)}"
        )
    return name


def distractor_classes(benchmark: str) -> tuple[int, ...]:
    """Return the distractor class ids of ``benchmark`` (empty for MOT15)."""
    name = normalize_benchmark(benchmark)
    if name == CLASSLESS_BENCHMARK:
        return ()
    if name == "MOT20":
        return MOT20_DISTRACTOR_CLASSES
    return DISTRACTOR_CLASSES


@dataclass(frozen=True)
class GtFrame:
    """All ground-truth rows of one frame, before preprocessing.

    ``classes`` is column 8 (unused for MOT15); ``zero_marked`` is column 7 (0 = ignore).
    """

    ids: np.ndarray
    boxes: np.ndarray
    classes: np.ndarray
    zero_marked: np.ndarray


@dataclass(frozen=True)
class TrackerFrame:
    """A tracker's ids and ``(x, y, w, h)`` boxes in one frame."""

    ids: np.ndarray
    boxes: np.ndarray


@dataclass(frozen=True)
class PreprocessedFrame:
    """One frame after MOTChallenge preprocessing.

    Holds the kept boxes, their ``(n', k')`` IoU (computed once, as TrackEval does) and
    ``gt_kept``/``tracker_kept`` masks over the input rows (False = removed).
    """

    gt_ids: np.ndarray
    gt_boxes: np.ndarray
    tracker_ids: np.ndarray
    tracker_boxes: np.ndarray
    iou: np.ndarray
    gt_kept: np.ndarray
    tracker_kept: np.ndarray


def _as_ids(values: np.ndarray | Sequence[int], what: str) -> np.ndarray:
    arr = np.asarray(values)
    if arr.ndim != 1:
        raise ValueError(f"{what} must be a 1-D array, got shape {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        as_int = arr.astype(np.int64)
        if not np.array_equal(as_int, arr):
            raise ValueError(f"{what} must hold integers, got {arr[as_int != arr][:3].tolist()}")
        arr = as_int
    return arr.astype(np.int64, copy=False)


def _as_boxes(values: np.ndarray, n: int, what: str) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64)
    if arr.size == 0 and n == 0:
        return arr.reshape(0, 4)
    if arr.shape != (n, 4):
        raise ValueError(f"{what} must have shape ({n}, 4), got {arr.shape}")
    return arr


def _check_unique(ids: np.ndarray, what: str) -> None:
    if ids.size:
        uniq, counts = np.unique(ids, return_counts=True)
        if counts.max() > 1:
            raise ValueError(
                f"{what} must be unique within a frame; repeated: {uniq[counts > 1].tolist()}"
            )


def preprocess_frame(
    gt_ids: np.ndarray,
    gt_boxes: np.ndarray,
    gt_classes: np.ndarray,
    gt_zero_marked: np.ndarray,
    trk_ids: np.ndarray,
    trk_boxes: np.ndarray,
    benchmark: str,
) -> PreprocessedFrame:
    """Apply MOTChallenge preprocessing to one frame (TrackEval 1.3.0 semantics).

    Input order is preserved. Raises ValueError on shape mismatches, duplicate ids, or (not
    MOT15) class ids outside 1..13 -- in every frame with ground truth, unlike TrackEval,
    so an invalid file fails whatever the tracker does.
    """
    name = normalize_benchmark(benchmark)
    g_ids = _as_ids(gt_ids, "gt_ids")
    g_boxes = _as_boxes(gt_boxes, len(g_ids), "gt_boxes")
    g_zero = _as_ids(gt_zero_marked, "gt_zero_marked")
    t_ids = _as_ids(trk_ids, "trk_ids")
    t_boxes = _as_boxes(trk_boxes, len(t_ids), "trk_boxes")
    if len(g_zero) != len(g_ids):
        raise ValueError(f"gt_zero_marked has {len(g_zero)} entries for {len(g_ids)} gt boxes")
    _check_unique(g_ids, "ground-truth ids")
    _check_unique(t_ids, "tracker ids")

    iou = box_iou(g_boxes, t_boxes)
    tracker_kept = np.ones(len(t_ids), dtype=bool)
    if name == CLASSLESS_BENCHMARK:
        gt_kept = g_zero != 0
    else:
        g_classes = _checked_classes(gt_classes, len(g_ids))
        if len(g_ids) and len(t_ids):
            tracker_kept[_on_distractors(iou, g_classes, name)] = False
        gt_kept = (g_zero != 0) & (g_classes == PEDESTRIAN_CLASS)

    return PreprocessedFrame(
        gt_ids=g_ids[gt_kept],
        gt_boxes=g_boxes[gt_kept],
        tracker_ids=t_ids[tracker_kept],
        tracker_boxes=t_boxes[tracker_kept],
        iou=iou[np.ix_(gt_kept, tracker_kept)],
        gt_kept=gt_kept,
        tracker_kept=tracker_kept,
    )


def _checked_classes(gt_classes: np.ndarray, count: int) -> np.ndarray:
    """The ground-truth class ids, one per box, all MOTChallenge classes."""
    g_classes = _as_ids(gt_classes, "gt_classes")
    if len(g_classes) != count:
        raise ValueError(f"gt_classes has {len(g_classes)} entries for {count} gt boxes")
    invalid = np.setdiff1d(g_classes, np.array(list(MOT_CLASS_IDS.values())))
    if invalid.size:
        raise ValueError(
            f"ground-truth class ids {invalid.tolist()} are not MOTChallenge classes "
            f"(valid: 1..{max(MOT_CLASS_IDS.values())}); if this is a 2D MOT 2015 file "
            f"without a class column, use benchmark='MOT15'"
        )
    return g_classes


def _on_distractors(iou: np.ndarray, g_classes: np.ndarray, benchmark: str) -> np.ndarray:
    """Columns of the tracker boxes matched (IoU >= 0.5, Hungarian) to distractor objects."""
    scores = iou.copy()
    scores[scores < MATCH_IOU_THRESHOLD - EPS] = 0.0
    rows, cols = linear_sum_assignment(-scores)
    matched = scores[rows, cols] > EPS
    rows, cols = rows[matched], cols[matched]
    on_distractor = np.isin(g_classes[rows], distractor_classes(benchmark))
    return cols[on_distractor]


def preprocess(gt: GtFrame, tracker: TrackerFrame, benchmark: str) -> PreprocessedFrame:
    """:func:`preprocess_frame` on records."""
    return preprocess_frame(
        gt.ids, gt.boxes, gt.classes, gt.zero_marked, tracker.ids, tracker.boxes, benchmark
    )


def _split_by_frame(rows: np.ndarray, num_frames: int, what: str) -> list[np.ndarray]:
    frames = rows[:, 0]
    frame_idx = frames.astype(np.int64)
    if rows.size and (
        not np.array_equal(frame_idx, frames) or frame_idx.min() < 1 or frame_idx.max() > num_frames
    ):
        bad = rows[(frame_idx != frames) | (frame_idx < 1) | (frame_idx > num_frames), 0]
        raise ValueError(
            f"{what} rows name frames {bad[:5].tolist()} outside 1..{num_frames} "
            "(MOTChallenge frames are 1-based integers)"
        )
    return [rows[frame_idx == t] for t in range(1, num_frames + 1)]


def gt_frames_from_rows(rows: np.ndarray, num_frames: int, *, benchmark: str) -> list[GtFrame]:
    """Split ``gt.txt`` rows into per-frame records (index ``t - 1`` holds frame ``t``).

    Columns by position as TrackEval reads them: frame, id, x, y, w, h, flag, class (not
    MOT15). Row order within a frame is kept.
    """
    name = normalize_benchmark(benchmark)
    arr = np.asarray(rows, dtype=np.float64)
    if arr.size == 0:
        arr = arr.reshape(0, 8)
    min_cols = 7 if name == CLASSLESS_BENCHMARK else 8
    if arr.ndim != 2 or arr.shape[1] < min_cols:
        raise ValueError(f"{name} ground truth needs at least {min_cols} columns, got {arr.shape}")
    out = []
    for part in _split_by_frame(arr, num_frames, "ground-truth"):
        classes = (
            part[:, 7].astype(np.int64)
            if part.shape[1] >= 8
            else np.full(len(part), PEDESTRIAN_CLASS, dtype=np.int64)
        )
        out.append(
            GtFrame(
                ids=part[:, 1].astype(np.int64),
                boxes=part[:, 2:6].copy(),
                classes=classes,
                zero_marked=part[:, 6].astype(np.int64),
            )
        )
    return out


def tracker_frames_from_rows(rows: np.ndarray, num_frames: int) -> list[TrackerFrame]:
    """Split MOTChallenge result rows ``(frame, id, x, y, w, h, ...)`` into per-frame records."""
    arr = np.asarray(rows, dtype=np.float64)
    if arr.size == 0:
        arr = arr.reshape(0, 6)
    if arr.ndim != 2 or arr.shape[1] < 6:
        raise ValueError(f"tracker rows need at least 6 columns, got shape {arr.shape}")
    return [
        TrackerFrame(ids=part[:, 1].astype(np.int64), boxes=part[:, 2:6].copy())
        for part in _split_by_frame(arr, num_frames, "tracker")
    ]
