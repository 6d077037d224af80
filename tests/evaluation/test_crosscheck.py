"""py-motmetrics and TrackEval agree on perturbed ground truth; on real tracker outputs the
cross-check reports where they differ and by which rule."""

from __future__ import annotations

import configparser
import shutil
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.evaluation.analysis.crosscheck import iou_distance, motmetrics_summary
from unitrack_env.metrics.mot_preprocess import (
    GtFrame,
    TrackerFrame,
    gt_frames_from_rows,
    tracker_frames_from_rows,
)
from unitrack_env.metrics.motchallenge import score_sequence

motmetrics = pytest.importorskip("motmetrics")

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data"
MOT17_TRAIN = DATA / "MOT17" / "train"
PETS = DATA / "MOT15" / "train" / "PETS09-S2L1"
TUD_DATA = Path(motmetrics.__file__).parent / "data"

COMPARED = ("MOTA", "IDF1", "IDSW", "CLR_TP", "CLR_FP", "CLR_FN", "IDTP", "IDFP", "IDFN")


def load_gt(seq_dir: Path) -> tuple[np.ndarray, int]:
    rows = np.loadtxt(seq_dir / "gt" / "gt.txt", delimiter=",", ndmin=2)
    ini = configparser.ConfigParser()
    ini.read(seq_dir / "seqinfo.ini")
    return rows, int(ini["Sequence"]["seqLength"])


def perturbed_tracker(gt_rows: np.ndarray, num_frames: int, seed: int, level: float) -> np.ndarray:
    """Deterministic imperfect tracker from every gt row: jitter, drops, id swaps, FPs."""
    rng = np.random.default_rng(seed)
    track_of = {int(g): int(g) + 1000 for g in np.unique(gt_rows[:, 1])}
    next_id = 5000
    out = []
    for t in range(1, num_frames + 1):
        frame_rows = gt_rows[gt_rows[:, 0] == t]
        present = [int(g) for g in frame_rows[:, 1]]
        if len(present) >= 2 and rng.random() < 0.4 * level:
            a, b = rng.choice(present, size=2, replace=False)
            track_of[a], track_of[b] = track_of[b], track_of[a]
        for row in frame_rows:
            if rng.random() < 0.15 * level:
                continue
            scale = 0.02 if rng.random() > 0.1 * level else 0.4
            x, y, w, h = row[2:6]
            x, y = x + rng.normal(0, scale) * w, y + rng.normal(0, scale) * h
            out.append([t, track_of[int(row[1])], x, y, w, h])
        for _ in range(rng.poisson(level)):
            out.append([t, next_id, *rng.uniform(0, 700, 2), *rng.uniform(20, 120, 2)])
            next_id += 1
    return np.array(out, dtype=np.float64).reshape(-1, 6)


def assert_agree(seq_dir: Path, gt_rows: np.ndarray, n: int, trk: np.ndarray, bench: str) -> None:
    mm = motmetrics_summary(
        gt_frames_from_rows(gt_rows, n, benchmark=bench),
        tracker_frames_from_rows(trk, n),
        benchmark=bench,
    )
    te = score_sequence(seq_dir, trk, benchmark=bench, seq_length=n)
    for key in COMPARED:
        assert mm[key] == pytest.approx(te[key], abs=1e-12), key
    assert 1.0 - mm["MOTP_distance"] == pytest.approx(te["MOTP"], abs=1e-9)


def test_iou_distance_marks_pairs_below_threshold() -> None:
    dist = iou_distance(np.array([[0.5, 0.4999], [1.0, 0.0]]))
    assert dist[0, 0] == 0.5 and np.isnan(dist[0, 1])
    assert dist[1, 0] == 0.0 and np.isnan(dist[1, 1])


def test_hand_built_switch() -> None:
    box = np.array([[0.0, 0.0, 10.0, 10.0]])
    gt = [GtFrame(np.array([1]), box, np.array([1]), np.array([1]))] * 3
    trk = [
        TrackerFrame(np.array([7]), box),
        TrackerFrame(np.array([8]), box),
        TrackerFrame(np.zeros(0, np.int64), np.zeros((0, 4))),
    ]
    out = motmetrics_summary(gt, trk, benchmark="MOT17")
    assert (out["CLR_TP"], out["CLR_FN"], out["IDSW"]) == (2, 1, 1)
    assert out["MOTA"] == pytest.approx((2 - 0 - 1) / 3)
    assert out["IDF1"] == pytest.approx(2 * 1 / (3 + 2))
    with pytest.raises(ValueError, match="3 ground-truth frames but 2 tracker frames"):
        motmetrics_summary(gt, trk[:2], benchmark="MOT17")


def test_tud_files_agree() -> None:
    if not (TUD_DATA / "TUD-Campus" / "gt.txt").is_file():
        pytest.skip("motmetrics wheel without its TUD data")
    gt = np.loadtxt(TUD_DATA / "TUD-Campus" / "gt.txt", delimiter=",")
    trk = np.loadtxt(TUD_DATA / "TUD-Campus" / "test.txt", delimiter=",")
    out = motmetrics_summary(
        gt_frames_from_rows(gt, 71, benchmark="MOT15"),
        tracker_frames_from_rows(trk, 71),
        benchmark="MOT15",
    )
    assert out["MOTA"] == pytest.approx(0.526462, abs=1e-6)
    assert out["IDF1"] == pytest.approx(0.557659, abs=1e-6)
    assert out["IDSW"] == 7


@pytest.mark.parametrize("level", [0.5, 1.5])
def test_mot17_clips_agree(level: float, tmp_path: Path) -> None:
    seqs = sorted(MOT17_TRAIN.glob("MOT17-*")) if MOT17_TRAIN.is_dir() else []
    if not seqs:
        pytest.skip(f"MOT17 fixtures not found under {MOT17_TRAIN}")
    for i, seq_dir in enumerate(seqs):
        gt_rows, n = load_gt(seq_dir)
        for seed in range(2):
            trk = perturbed_tracker(gt_rows, n, seed=10 * i + seed, level=level)
            assert_agree(seq_dir, gt_rows, n, trk, "MOT17")


@pytest.mark.parametrize("seed,level", [(0, 0.3), (1, 1.0)])
def test_pets09_agrees(seed: int, level: float, tmp_path: Path) -> None:
    if not (PETS / "gt" / "gt.txt").is_file():
        pytest.skip(f"PETS09-S2L1 fixture not found under {PETS}")
    gt_rows, n = load_gt(PETS)
    trk = perturbed_tracker(gt_rows, n, seed=seed, level=level)
    assert_agree(PETS, gt_rows, n, trk, "MOT15")


def test_gt_copy_without_seqinfo(tmp_path: Path) -> None:
    # the cross-check needs only rows; TrackEval gets the length explicitly
    if not (PETS / "gt" / "gt.txt").is_file():
        pytest.skip(f"PETS09-S2L1 fixture not found under {PETS}")
    seq_dir = tmp_path / "PETS09-S2L1"
    (seq_dir / "gt").mkdir(parents=True)
    shutil.copy(PETS / "gt" / "gt.txt", seq_dir / "gt" / "gt.txt")
    gt_rows, n = load_gt(PETS)
    trk = perturbed_tracker(gt_rows, n, seed=5, level=0.8)
    assert_agree(seq_dir, gt_rows, n, trk, "MOT15")


# ---------------------------------------------------------------- real tracker outputs
def test_numpy_2_without_asfarray_is_not_patched() -> None:
    # motmetrics 1.4.0's iou_matrix needs np.asfarray (gone in NumPy 2); the cross-check never
    # calls it and must not put it back into the user's NumPy.
    had = hasattr(np, "asfarray")
    box = np.array([[0.0, 0.0, 10.0, 10.0]])
    gt = [GtFrame(np.array([1]), box, np.array([1]), np.array([1]))]
    motmetrics_summary(gt, [TrackerFrame(np.array([7]), box)], benchmark="MOT17")
    assert hasattr(np, "asfarray") == had
    if int(np.__version__.split(".")[0]) >= 2:
        assert not had


def test_iou_tracker_on_pets09_differs_by_the_continuation_rule(tmp_path: Path) -> None:
    # The `iou` agent's real output on PETS09-S2L1: motmetrics continues gt 1's match to
    # tracker 57 from frame 303 at frame 306 (TrackEval only continues frame 305's record,
    # where gt 1 was missed), so it counts one more TP and a higher MOTA.
    from unitrack_env.evaluation.analysis.crosscheck import (
        CONTINUATION,
        DISPLACED,
        crosscheck_sequence,
    )
    from unitrack_env.evaluation.run.runner import run

    if not (PETS / "gt" / "gt.txt").is_file():
        pytest.skip(f"PETS09-S2L1 fixture not found under {PETS}")
    run("UniTrack/MOT15-v0", "iou", out=tmp_path / "iou", progress=False,
        env_kwargs={"root": str(PETS.parents[1]), "decode_frames": False})
    check = crosscheck_sequence(PETS, tmp_path / "iou" / "data" / "PETS09-S2L1.txt",
                                benchmark="MOT15")
    diff = check.differences()
    assert set(diff) == {"MOTA", "CLR_TP", "CLR_FP", "CLR_FN"}
    assert diff["CLR_TP"] == (1958, 1959) and diff["MOTA"][1] > diff["MOTA"][0]
    assert [(p.frame, p.gt_id, p.rule) for p in check.pairs] == [
        (306, 1, CONTINUATION), (306, 13, DISPLACED)]
    assert check.pairs[0].last_frame == 303 and check.pairs[0].trackeval is None
    report = check.report("PETS09-S2L1")
    assert "continuation rule" in report and "from frame 303" in report
    # TrackEval's side of the report is TrackEval's own scoring.
    assert check.trackeval["MOTA"] == score_sequence(
        PETS, tmp_path / "iou" / "data" / "PETS09-S2L1.txt", benchmark="MOT15")["MOTA"]


def test_agreement_is_reported_as_such() -> None:
    from unitrack_env.evaluation.analysis.crosscheck import crosscheck_frames

    box = np.array([[0.0, 0.0, 10.0, 10.0]])
    gt = [GtFrame(np.array([1]), box, np.array([1]), np.array([1]))] * 2
    trk = [TrackerFrame(np.array([7]), box)] * 2
    te = {"MOTA": 1.0, "IDF1": 1.0, "IDSW": 0.0, "CLR_TP": 2.0, "CLR_FP": 0.0, "CLR_FN": 0.0,
          "IDTP": 2.0, "IDFP": 0.0, "IDFN": 0.0}
    check = crosscheck_frames(gt, trk, te, benchmark="MOT17")
    assert not check.pairs and not check.differences()
    assert "agree exactly" in check.report()
