"""Per-frame MOTChallenge preprocessing and streaming CLEAR.

Three layers: hand-built frames with known answers; then the real MOT17 clips and PETS09-S2L1
with deterministic perturbed trackers, whose per-frame sums must equal TrackEval's CLEAR
exactly.
"""

from __future__ import annotations

import configparser
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.metrics.clear_stream import FrameClear, StreamingClear, clear_from_frames
from unitrack_env.metrics.mot_preprocess import (
    gt_frames_from_rows,
    preprocess,
    preprocess_frame,
    tracker_frames_from_rows,
)
from unitrack_env.metrics.motchallenge import score_sequence

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data"
MOT17_TRAIN = DATA / "MOT17" / "train"
PETS = DATA / "MOT15" / "train" / "PETS09-S2L1"


def box(x: float, y: float, w: float = 10.0, h: float = 10.0) -> np.ndarray:
    return np.array([[x, y, w, h]], dtype=np.float64)


def boxes(*rows: tuple[float, float]) -> np.ndarray:
    return np.concatenate([box(x, y) for x, y in rows]) if rows else np.zeros((0, 4))


IDS = np.array
NONE = np.zeros(0, dtype=np.int64)


# --------------------------------------------------------------------------- preprocessing


def test_tracker_boxes_on_distractor_classes_are_removed() -> None:
    # gt: pedestrian, static person (7), distractor (8), car (3), zero-marked pedestrian
    gt_boxes = boxes((0, 0), (100, 0), (200, 0), (300, 0), (400, 0))
    frame = preprocess_frame(
        IDS([1, 2, 3, 4, 5]),
        gt_boxes,
        IDS([1, 7, 8, 3, 1]),
        IDS([1, 1, 1, 1, 0]),
        IDS([10, 20, 30, 40, 50, 60]),
        np.concatenate([gt_boxes, box(900, 900)]),
        "MOT17",
    )
    assert frame.gt_ids.tolist() == [1]
    # the boxes on the static person and the distractor vanish; the car, the zero-marked
    # pedestrian and the unmatched box stay (they will be false positives)
    assert frame.tracker_ids.tolist() == [10, 40, 50, 60]
    assert frame.tracker_kept.tolist() == [True, False, False, True, True, True]
    assert frame.iou.shape == (1, 4)
    assert frame.iou[0, 0] == pytest.approx(1.0)


def test_non_mot_vehicle_is_a_distractor_only_for_mot20() -> None:
    args = (IDS([1]), box(0, 0), IDS([6]), IDS([1]), IDS([9]), box(0, 0))
    assert preprocess_frame(*args, "MOT17").tracker_ids.tolist() == [9]
    assert preprocess_frame(*args, "MOT16").tracker_ids.tolist() == [9]
    assert preprocess_frame(*args, "MOT20").tracker_ids.tolist() == []


def test_distractor_removal_uses_a_one_to_one_hungarian_match() -> None:
    # One tracker box overlaps a distractor (IoU 0.6) and a pedestrian (IoU 0.9): the optimal
    # one-to-one match gives it to the pedestrian, so it is kept.
    ped, distractor = box(0, 0, 100, 100), box(-25, 0, 100, 100)
    trk = box(-5, 0, 100, 100)
    frame = preprocess_frame(
        IDS([1, 2]),
        np.concatenate([ped, distractor]),
        IDS([1, 8]),
        IDS([1, 1]),
        IDS([7]),
        trk,
        "MOT17",
    )
    assert frame.tracker_ids.tolist() == [7]
    # with a second tracker box on the distractor, that one is removed instead
    frame = preprocess_frame(
        IDS([1, 2]),
        np.concatenate([ped, distractor]),
        IDS([1, 8]),
        IDS([1, 1]),
        IDS([7, 8]),
        np.concatenate([trk, distractor]),
        "MOT17",
    )
    assert frame.tracker_ids.tolist() == [7]


def test_distractor_match_needs_iou_one_half() -> None:
    gt = box(0, 0, 100, 100)
    half = box(0, 0, 50, 100)  # IoU exactly 0.5 -> matched -> removed
    below = box(0, 0, 49, 100)  # IoU 0.49 -> not matched -> kept
    for trk, kept in ((half, []), (below, [3])):
        frame = preprocess_frame(IDS([1]), gt, IDS([7]), IDS([1]), IDS([3]), trk, "MOT17")
        assert frame.tracker_ids.tolist() == kept


def test_mot15_keeps_flagged_boxes_and_ignores_classes() -> None:
    gt_boxes = boxes((0, 0), (100, 0))
    frame = preprocess_frame(
        IDS([1, 2]), gt_boxes, IDS([-4, 99]), IDS([1, 0]), IDS([5, 6]), gt_boxes, "MOT15"
    )
    assert frame.gt_ids.tolist() == [1]
    assert frame.tracker_ids.tolist() == [5, 6]  # no distractor removal in MOT15


def test_invalid_classes_raise_a_clear_error() -> None:
    with pytest.raises(ValueError, match=r"class ids \[14\].*benchmark='MOT15'"):
        preprocess_frame(IDS([1]), box(0, 0), IDS([14]), IDS([1]), NONE, boxes(), "MOT17")


def test_bad_inputs_raise() -> None:
    with pytest.raises(ValueError, match="unknown MOTChallenge benchmark 'MOT18'"):
        preprocess_frame(NONE, boxes(), NONE, NONE, NONE, boxes(), "MOT18")
    with pytest.raises(ValueError, match=r"tracker ids must be unique.*\[4\]"):
        preprocess_frame(NONE, boxes(), NONE, NONE, IDS([4, 4]), boxes((0, 0), (5, 5)), "MOT17")
    with pytest.raises(ValueError, match=r"gt_boxes must have shape \(2, 4\)"):
        preprocess_frame(IDS([1, 2]), box(0, 0), IDS([1, 1]), IDS([1, 1]), NONE, boxes(), "MOT17")


def test_frames_from_rows_split_by_frame_and_keep_order() -> None:
    rows = np.array(
        [[2, 5, 0, 0, 1, 1, 1, 1, 1.0], [1, 3, 0, 0, 1, 1, 0, 7, 1.0], [2, 4, 0, 0, 1, 1, 1, 1, 1]]
    )
    frames = gt_frames_from_rows(rows, 3, benchmark="MOT17")
    assert [f.ids.tolist() for f in frames] == [[3], [5, 4], []]
    assert frames[0].classes.tolist() == [7] and frames[0].zero_marked.tolist() == [0]
    with pytest.raises(ValueError, match=r"frames \[2.0, 1.5\] outside 1..1"):
        tracker_frames_from_rows(np.array([[2, 1, 0, 0, 1, 1], [1.5, 1, 0, 0, 1, 1]]), 1)


# --------------------------------------------------------------------------- streaming CLEAR


def test_perfect_tracking() -> None:
    clear = StreamingClear()
    for t in range(3):
        out = clear.update(IDS([1, 2]), boxes((t, 0), (50, t)), IDS([7, 8]), boxes((t, 0), (50, t)))
        assert out == FrameClear(tp=2, fp=0, fn=0, idsw=0, iou_sum=2.0)
    assert clear.totals.mota == 1.0 and clear.totals.motp == 1.0 and clear.totals.frames == 3


def test_counts_fp_fn_and_switch() -> None:
    clear = StreamingClear()
    clear.update(IDS([1]), box(0, 0), IDS([7]), box(0, 0))
    out = clear.update(IDS([1, 2]), boxes((0, 0), (50, 50)), IDS([8, 9]), boxes((0, 0), (90, 90)))
    assert (out.tp, out.fp, out.fn, out.idsw) == (1, 1, 1, 1)
    assert out.mota_numerator == 1 - 1 - 1
    assert clear.totals.mota == (2 - 1 - 1) / 3


def test_iou_threshold_is_inclusive() -> None:
    gt = box(0, 0, 100, 100)
    assert StreamingClear().update(IDS([1]), gt, IDS([2]), box(0, 0, 50, 100)).tp == 1
    assert StreamingClear().update(IDS([1]), gt, IDS([2]), box(0, 0, 49, 100)).tp == 0


def test_previous_match_wins_over_a_better_overlap() -> None:
    gt = box(0, 0, 100, 100)
    near, nearer = box(20, 0, 100, 100), box(5, 0, 100, 100)  # IoU 0.67 and 0.90
    clear = StreamingClear()
    clear.update(IDS([1]), gt, IDS([7]), near)
    out = clear.update(IDS([1]), gt, IDS([7, 8]), np.concatenate([near, nearer]))
    assert (out.tp, out.fp, out.idsw) == (1, 1, 0)
    assert out.iou_sum == pytest.approx(80 / 120)
    # without the history the better overlap wins
    fresh = StreamingClear().update(IDS([1]), gt, IDS([7, 8]), np.concatenate([near, nearer]))
    assert fresh.iou_sum == pytest.approx(0.95 / 1.05)


def test_switch_counts_against_the_last_match_any_time_before() -> None:
    gt = box(0, 0)
    clear = StreamingClear()
    clear.update(IDS([1]), gt, IDS([7]), gt)
    clear.update(IDS([1]), gt, NONE, boxes())  # missed
    clear.update(NONE, boxes(), IDS([7]), gt)  # gt absent: the box is a false positive
    assert clear.update(IDS([1]), gt, IDS([8]), gt).idsw == 1
    assert clear.update(IDS([1]), gt, IDS([7]), gt).idsw == 1  # back to 7 is a switch too
    assert (clear.totals.tp, clear.totals.fp, clear.totals.fn, clear.totals.idsw) == (3, 1, 1, 2)


def test_frames_without_tracker_boxes_keep_the_continuity_bonus() -> None:
    # TrackEval skips the bookkeeping in frames where one side is empty, so the previous
    # match stays "the previous timestep's" across them; a frame with both sides resets it.
    gt = box(0, 0, 100, 100)
    near, nearer = box(20, 0, 100, 100), box(5, 0, 100, 100)
    both = np.concatenate([near, nearer])

    clear = StreamingClear()
    clear.update(IDS([1]), gt, IDS([7]), near)
    clear.update(IDS([1]), gt, NONE, boxes())  # empty tracker frame
    assert clear.update(IDS([1]), gt, IDS([7, 8]), both).idsw == 0

    clear.reset()
    clear.update(IDS([1]), gt, IDS([7]), near)
    clear.update(IDS([1]), gt, IDS([7]), box(500, 500))  # both sides present, no match
    assert clear.update(IDS([1]), gt, IDS([7, 8]), both).idsw == 1  # 8 wins, a switch


def test_reset_forgets_everything() -> None:
    clear = StreamingClear()
    clear.update(IDS([1]), box(0, 0), IDS([7]), box(0, 0))
    clear.reset()
    assert clear.totals.frames == 0
    assert clear.update(IDS([1]), box(0, 0), IDS([8]), box(0, 0)).idsw == 0


def test_instances_do_not_share_state() -> None:
    a, b = StreamingClear(), StreamingClear()
    a.update(IDS([1]), box(0, 0), IDS([7]), box(0, 0))
    assert b.update(IDS([1]), box(0, 0), IDS([8]), box(0, 0)).idsw == 0
    assert b.totals.frames == 1 and a.totals.frames == 1


def test_iou_shape_is_checked() -> None:
    with pytest.raises(ValueError, match="IoU matrix has shape"):
        StreamingClear().update(IDS([1]), box(0, 0), IDS([7]), box(0, 0), iou=np.zeros((2, 2)))


# --------------------------------------------------------------------------- real data


def load_gt(seq_dir: Path) -> tuple[np.ndarray, int]:
    """Tiny local loader: gt rows by position and seqLength from seqinfo.ini."""
    rows = np.loadtxt(seq_dir / "gt" / "gt.txt", delimiter=",", ndmin=2)
    ini = configparser.ConfigParser()
    ini.read(seq_dir / "seqinfo.ini")
    return rows, int(ini["Sequence"]["seqLength"])


def perturbed_tracker(gt_rows: np.ndarray, num_frames: int, seed: int, level: float) -> np.ndarray:
    """A deterministic imperfect tracker built from every gt row (all classes).

    Jitter (some boxes pushed below IoU 0.5), dropped boxes, empty frames, persistent id
    swaps, new ids, duplicate boxes and random false positives; rows on distractor classes,
    vehicles and zero-marked boxes are kept so that preprocessing has work to do.
    """
    rng = np.random.default_rng(seed)
    track_of = {int(g): int(g) + 1000 for g in np.unique(gt_rows[:, 1])}
    next_id = 5000
    out: list[list[float]] = []
    for t in range(1, num_frames + 1):
        frame_rows = gt_rows[gt_rows[:, 0] == t]
        present = [int(g) for g in frame_rows[:, 1]]
        if len(present) >= 2 and rng.random() < 0.4 * level:  # swap two identities
            a, b = rng.choice(present, size=2, replace=False)
            track_of[a], track_of[b] = track_of[b], track_of[a]
        if present and rng.random() < 0.2 * level:  # a track gets a fresh id
            g = int(rng.choice(present))
            track_of[g] = next_id
            next_id += 1
        blackout = rng.random() < 0.05 * level  # the tracker outputs nothing this frame
        for row in frame_rows[rng.permutation(len(frame_rows))]:
            if blackout or rng.random() < 0.15 * level:
                continue
            x, y, w, h = row[2:6]
            scale = 0.02 if rng.random() > 0.1 * level else 0.4
            if level > 0:
                x, y = x + rng.normal(0, scale) * w, y + rng.normal(0, scale) * h
                w, h = w * np.exp(rng.normal(0, scale)), h * np.exp(rng.normal(0, scale))
            out.append([t, track_of[int(row[1])], x, y, w, h, 1, -1, -1, -1])
            if rng.random() < 0.05 * level:  # a duplicate box on the same object
                out.append([t, next_id, x + 0.1 * w, y, w, h, 1, -1, -1, -1])
                next_id += 1
        for _ in range(0 if blackout else rng.poisson(1.0 * level)):  # false positives
            out.append(
                [t, next_id, *rng.uniform(0, 700, 2), *rng.uniform(20, 120, 2), 1, -1, -1, -1]
            )
            next_id += 1
    return np.array(out, dtype=np.float64).reshape(-1, 10)


def mot17_sequences() -> list[Path]:
    return sorted(MOT17_TRAIN.glob("MOT17-*")) if MOT17_TRAIN.is_dir() else []


def check_against_trackeval(seq_dir: Path, benchmark: str, seed: int, level: float) -> None:
    gt_rows, num_frames = load_gt(seq_dir)
    trk_rows = perturbed_tracker(gt_rows, num_frames, seed, level)
    gt_frames = gt_frames_from_rows(gt_rows, num_frames, benchmark=benchmark)
    trk_frames = tracker_frames_from_rows(trk_rows, num_frames)

    clear = StreamingClear()
    sums = np.zeros(4, dtype=np.int64)
    removed = 0
    for gt, trk in zip(gt_frames, trk_frames, strict=True):
        frame = preprocess(gt, trk, benchmark)
        removed += int((~frame.tracker_kept).sum())
        out = clear.update(frame.gt_ids, frame.gt_boxes, frame.tracker_ids, frame.tracker_boxes)
        sums += (out.tp, out.fp, out.fn, out.idsw)
    tp, fp, fn, idsw = sums.tolist()

    official = score_sequence(seq_dir, trk_rows, benchmark=benchmark)
    assert (tp, fp, fn, idsw) == (
        official["CLR_TP"],
        official["CLR_FP"],
        official["CLR_FN"],
        official["IDSW"],
    )
    assert (tp - fp - idsw) / (tp + fn) == official["MOTA"]
    assert clear.totals.motp == pytest.approx(official["MOTP"], abs=1e-12)
    totals = clear_from_frames(gt_frames, trk_frames, benchmark=benchmark)
    assert (totals.tp, totals.fp, totals.fn, totals.idsw) == (tp, fp, fn, idsw)
    if benchmark != "MOT15" and level > 0:
        assert removed > 0, "the perturbed tracker should hit distractor classes"


@pytest.mark.parametrize("level", [0.0, 0.5, 1.0, 2.0])
def test_mot17_clips_match_trackeval_clear(level: float) -> None:
    seqs = mot17_sequences()
    if not seqs:
        pytest.skip(f"MOT17 fixtures not found under {MOT17_TRAIN}")
    for i, seq_dir in enumerate(seqs):
        for seed in range(3):
            check_against_trackeval(seq_dir, "MOT17", seed=100 * i + seed, level=level)


def test_mot17_clip_perturbation_produces_switches() -> None:
    seqs = mot17_sequences()
    if not seqs:
        pytest.skip(f"MOT17 fixtures not found under {MOT17_TRAIN}")
    gt_rows, n = load_gt(seqs[1])
    trk = perturbed_tracker(gt_rows, n, seed=3, level=2.0)
    totals = clear_from_frames(
        gt_frames_from_rows(gt_rows, n, benchmark="MOT17"),
        tracker_frames_from_rows(trk, n),
        benchmark="MOT17",
    )
    assert totals.idsw > 0 and totals.fp > 0 and totals.fn > 0 and totals.tp > 0


@pytest.mark.parametrize("seed,level", [(0, 0.0), (1, 0.5), (2, 1.0)])
def test_pets09_matches_trackeval_clear(seed: int, level: float) -> None:
    if not (PETS / "gt" / "gt.txt").is_file():
        pytest.skip(f"PETS09-S2L1 fixture not found under {PETS}")
    check_against_trackeval(PETS, "MOT15", seed=seed, level=level)
