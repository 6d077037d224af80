"""Known-answer tests for the propagation metrics: OTB success/precision, DAVIS J/F, PCK."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from unitrack_env.metrics import pose, sot, vos

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data"


# --------------------------------------------------------------------------- SOT (OTB)


def _track(n: int, box=(10.0, 20.0, 10.0, 10.0)) -> np.ndarray:
    return np.tile(np.asarray(box, dtype=float), (n, 1))


def test_thresholds_are_the_toolkit_grids():
    assert len(sot.OTB_OVERLAP_THRESHOLDS) == 21
    assert sot.OTB_OVERLAP_THRESHOLDS[7] == pytest.approx(0.35)
    assert sot.OTB_CENTER_THRESHOLDS.tolist() == list(range(51))


def test_perfect_tracker_scores_twenty_of_twentyone():
    gt = _track(6) + np.arange(6)[:, None]  # moving target
    s = sot.evaluate_sot_sequence(gt.copy(), gt)
    # IoU 1 passes every threshold except 1.0 itself ("> t", strict), so AUC = 20/21.
    assert s.auc == pytest.approx(20 / 21)
    assert s.success_curve[-1] == 0.0 and np.all(s.success_curve[:-1] == 1.0)
    assert s.precision_20px == 1.0 and np.all(s.precision_curve == 1.0)
    assert s.average_overlap == 1.0


def test_constant_shift_with_iou_one_third():
    gt = _track(5)
    pred = gt + [5.0, 0.0, 0.0, 0.0]  # half-width shift: IoU = 50 / 150 = 1/3
    np.testing.assert_allclose(sot.overlap_per_frame(pred, gt), 1 / 3)
    s = sot.evaluate_sot_sequence(pred, gt, init_from_gt=False)
    # 1/3 exceeds the 7 thresholds 0, 0.05, ..., 0.30 -> AUC = 7/21.
    assert s.auc == pytest.approx(7 / 21)
    # Centre error 5 px fails thresholds 0..4 and passes 5..50.
    assert s.precision_curve[:5].tolist() == [0.0] * 5
    assert np.all(s.precision_curve[5:] == 1.0)
    assert s.precision_20px == 1.0


def test_first_frame_is_replaced_by_ground_truth():
    gt = _track(4)
    pred = gt + [5.0, 0.0, 0.0, 0.0]
    s = sot.evaluate_sot_sequence(pred, gt)  # frame 0 perfect, 3 frames at IoU 1/3
    expected = (7 * 1.0 + 13 * 0.25 + 0.0) / 21
    assert s.auc == pytest.approx(expected)


def test_success_uses_strictly_greater():
    gt = _track(3)
    pred = np.tile([10.0, 20.0, 10.0, 5.0], (3, 1))  # inside GT, IoU exactly 0.5
    s = sot.evaluate_sot_sequence(pred, gt, init_from_gt=False)
    assert s.success_curve[10] == 0.0  # threshold 0.5: 0.5 > 0.5 is false
    assert s.success_curve[9] == 1.0
    assert s.auc == pytest.approx(10 / 21)


def test_far_tracker_fails_precision_at_20px():
    gt = _track(3)
    s = sot.evaluate_sot_sequence(gt + [30.0, 0, 0, 0], gt, init_from_gt=False)
    assert s.precision_20px == 0.0 and s.auc == 0.0
    assert s.precision_curve[30] == 1.0


def test_invalid_ground_truth_toolkit_versus_exclude():
    gt = _track(4)
    gt[2] = [10.0, 20.0, 0.0, 10.0]  # w = 0: target absent
    pred = _track(4)
    toolkit = sot.evaluate_sot_sequence(pred, gt)
    # Toolkit: the invalid frame fails every success threshold but passes every precision one.
    assert toolkit.success_curve[0] == pytest.approx(3 / 4)
    assert toolkit.precision_20px == 1.0
    assert toolkit.num_frames == 4
    excluded = sot.evaluate_sot_sequence(pred, gt, invalid_gt="exclude")
    assert excluded.success_curve[0] == 1.0 and excluded.num_frames == 3
    assert excluded.auc == pytest.approx(20 / 21)


def test_toolkit_validity_requires_positive_x_and_y():
    gt = np.array([[0.0, 5.0, 10.0, 10.0], [3.0, 5.0, 10.0, 10.0], [np.nan] * 4])
    assert sot.valid_ground_truth(gt, "toolkit").tolist() == [False, True, False]
    assert sot.valid_ground_truth(gt, "exclude").tolist() == [True, True, False]
    with pytest.raises(ValueError, match="toolkit"):
        sot.valid_ground_truth(gt, "bogus")  # type: ignore[arg-type]


def test_broken_predictions_repeat_the_previous_box():
    gt = _track(4)
    pred = gt.copy()
    pred[2] = np.nan
    pred[3] = [0.0, 0.0, -1.0, 5.0]
    repaired = sot.repair_predictions(pred, gt)
    np.testing.assert_array_equal(repaired[2], pred[1])
    np.testing.assert_array_equal(repaired[3], pred[1])
    assert sot.evaluate_sot_sequence(pred, gt).auc == pytest.approx(20 / 21)


def test_overlap_matches_the_toolkit_pixel_convention():
    # calcRectInt.m: right = x + w - 1, intersection + 1  ==  continuous IoU with x2 = x + w.
    a = np.array([[1.0, 1.0, 4.0, 3.0]])
    b = np.array([[3.0, 2.0, 5.0, 5.0]])
    iw = min(1 + 4 - 1, 3 + 5 - 1) - max(1, 3) + 1
    ih = min(1 + 3 - 1, 2 + 5 - 1) - max(1, 2) + 1
    inter = iw * ih
    expected = inter / (12 + 25 - inter)
    assert sot.overlap_per_frame(a, b)[0] == pytest.approx(expected)


def test_frame_iou_and_shape_errors():
    assert sot.frame_iou(np.array([0, 0, 2, 2]), np.array([1, 0, 2, 2])) == pytest.approx(1 / 3)
    assert sot.frame_iou(np.array([0, 0, 2, 2]), np.array([np.nan] * 4)) == 0.0
    with pytest.raises(ValueError, match="one prediction per frame"):
        sot.evaluate_sot_sequence(_track(3), _track(4))
    with pytest.raises(ValueError, match=r"\(n, 4\)"):
        sot.overlap_per_frame(np.zeros((2, 3)), np.zeros((2, 3)))


def test_aggregate_is_the_mean_over_sequences():
    gt = _track(5)
    a = sot.evaluate_sot_sequence(gt, gt)
    b = sot.evaluate_sot_sequence(gt + [5.0, 0, 0, 0], gt, init_from_gt=False)
    total = sot.aggregate_sot([a, b])
    assert total.auc == pytest.approx((20 / 21 + 7 / 21) / 2)
    assert total.num_sequences == 2 and total.num_frames == 10
    assert set(total.as_dict()) == {"AUC", "Precision@20px", "AverageOverlap"}


# --------------------------------------------------------------------------- VOS (DAVIS)


def _square(shape=(60, 80), top=10, left=10, size=20) -> np.ndarray:
    m = np.zeros(shape, dtype=bool)
    m[top : top + size, left : left + size] = True
    return m


def test_region_similarity_known_values():
    gt = _square()
    shifted = _square(left=20)  # overlap 20x10 of two 20x20 squares: 200 / 600
    assert vos.region_similarity(gt, shifted) == pytest.approx(1 / 3)
    assert vos.region_similarity(gt, gt) == 1.0
    assert vos.region_similarity(np.zeros((4, 4)), np.zeros((4, 4))) == 1.0  # DAVIS: empty=1
    assert vos.region_similarity(gt, np.zeros_like(gt)) == 0.0


def test_void_pixels_are_not_scored():
    gt = _square()
    pred = gt | _square(left=40, size=10)  # extra 100 px, all inside void
    void = _square(left=40, size=10)
    assert vos.region_similarity(gt, pred) == pytest.approx(400 / 500)
    assert vos.region_similarity(gt, pred, void) == 1.0
    assert vos.boundary_measure(gt, pred, void) == 1.0


def test_boundary_map_is_seg2bmap():
    # A 2x2 square at rows/cols 2-3: a pixel is on the boundary when it differs from its
    # right, lower or lower-right neighbour (worked out by hand).
    bmap = vos.boundary_map(_square((6, 6), 2, 2, 2))
    expected = [
        [0, 0, 0, 0, 0, 0],
        [0, 1, 1, 1, 0, 0],
        [0, 1, 0, 1, 0, 0],
        [0, 1, 1, 1, 0, 0],
        [0, 0, 0, 0, 0, 0],
        [0, 0, 0, 0, 0, 0],
    ]
    assert bmap.astype(int).tolist() == expected
    # The image border is not a boundary: a full mask has none.
    assert not vos.boundary_map(np.ones((4, 5), dtype=bool)).any()


def test_disk_matches_skimage():
    morphology = pytest.importorskip("skimage.morphology")
    for r in (0, 1, 3, 8):
        np.testing.assert_array_equal(vos.disk_footprint(r), morphology.disk(r))
    with pytest.raises(ValueError):
        vos.disk_footprint(2.5)


def test_boundary_measure_known_values():
    gt = _square((480, 854), 100, 100, 100)
    assert vos.boundary_tolerance_px(gt.shape) == 8  # ceil(0.008 * 979.6)
    assert vos.boundary_measure(gt, gt) == 1.0
    assert vos.boundary_measure(gt, _square((480, 854), 103, 104, 100)) == 1.0  # within 8 px
    assert vos.boundary_measure(gt, np.zeros_like(gt)) == 0.0
    assert vos.boundary_measure(np.zeros_like(gt), np.zeros_like(gt)) == 1.0
    far = _square((480, 854), 300, 600, 50)
    assert vos.boundary_measure(gt, far) == 0.0


_PYCOCOTOOLS_NUMPY2 = "ignore:__array__ implementation doesn't accept a copy keyword"


def _trackeval_jf():
    pytest.importorskip("pycocotools")
    pytest.importorskip("skimage")
    from trackeval.metrics.j_and_f import JAndF

    from unitrack_env.datasets.rle import mask_api as mask_utils

    def rle(m: np.ndarray):
        return mask_utils.encode(np.asfortranarray(m.astype(np.uint8)))

    return JAndF, rle


@pytest.mark.filterwarnings(_PYCOCOTOOLS_NUMPY2)
@pytest.mark.parametrize(("dy", "dx", "size"), [(0, 0, 100), (3, 4, 100), (0, 12, 90),
                                                 (15, 20, 60), (40, -30, 120)])
def test_f_and_j_agree_with_trackeval(dy, dx, size):
    jandf, rle = _trackeval_jf()
    gt = _square((480, 854), 150, 300, 100)
    pred = _square((480, 854), 150 + dy, 300 + dx, size)
    ref_f = jandf._compute_f([[rle(gt)]], [[rle(pred)]], 0, 0, 0.008)[0]
    ref_j = jandf._compute_j([[rle(gt)]], [[rle(pred)]], 1, 1, 1)[0, 0, 0]
    assert vos.boundary_measure(gt, pred) == pytest.approx(ref_f, abs=1e-12)
    assert vos.region_similarity(gt, pred) == pytest.approx(ref_j, abs=1e-12)


@pytest.mark.filterwarnings(_PYCOCOTOOLS_NUMPY2)
def test_boundary_map_agrees_with_trackeval_on_random_masks():
    jandf, _ = _trackeval_jf()
    rng = np.random.default_rng(0)
    for _ in range(5):
        m = rng.random((23, 31)) > 0.6
        np.testing.assert_array_equal(vos.boundary_map(m), jandf._seg2bmap(m.copy()))


def test_davis_statistics_known_values():
    mean, recall, decay = vos.davis_statistics(np.array([1.0, 1.0, 0.0, 0.0, 0.0]))
    assert mean == pytest.approx(0.4)
    assert recall == pytest.approx(0.4)
    assert decay == pytest.approx(1.0)  # bins [0:2] and [3:5]
    assert all(np.isnan(vos.davis_statistics(np.array([]))))


def test_sequence_scores_drop_first_and_last_frames():
    gt_labels = np.zeros((5, 60, 80), dtype=np.uint8)
    gt_labels[:, 10:30, 10:30] = 1
    gt_labels[:, 40:50, 50:70] = 2
    pred = gt_labels.copy()
    pred[0] = 0  # frame 0 and the last frame are not scored
    pred[4] = 0
    pred[2][pred[2] == 2] = 0  # object 2 missed in frame 2 -> J = 0
    res = vos.evaluate_vos_sequence(gt_labels, pred, (1, 2), sequence_name="toy")
    assert res.object_names == ("toy_1", "toy_2")
    np.testing.assert_allclose(res.j_per_frame[0], [1.0, 1.0, 1.0])
    np.testing.assert_allclose(res.j_per_frame[1], [1.0, 0.0, 1.0])
    assert res.summary["J-Mean"] == pytest.approx((1.0 + 2 / 3) / 2)
    assert res.summary["F-Mean"] == pytest.approx((1.0 + 2 / 3) / 2)
    assert res.j_and_f == pytest.approx((1.0 + 2 / 3) / 2)
    full = vos.evaluate_vos_sequence(gt_labels, pred, (1, 2), exclude_first_last=False)
    assert full.j_per_frame[0].tolist() == [0.0, 1.0, 1.0, 1.0, 0.0]
    pooled = vos.aggregate_vos([res, full])
    assert pooled.num_objects == 4


def test_frame_j_is_the_mean_over_objects_and_rejects_unknown_labels():
    gt = np.zeros((10, 10), dtype=np.uint8)
    gt[:5, :5] = 1
    gt[5:, 5:] = 2
    gt[0, 9] = vos.DAVIS_VOID_LABEL
    pred = gt.copy()
    pred[0, 9] = 0
    pred[pred == 2] = 0
    assert vos.frame_j(gt, pred, (1, 2)) == pytest.approx(0.5)
    pred[0, 0] = 3
    with pytest.raises(ValueError, match=r"labels \[3\]"):
        vos.frame_j(gt, pred, (1, 2))


@pytest.mark.filterwarnings(_PYCOCOTOOLS_NUMPY2)
def test_real_davis_masks_against_themselves_and_trackeval():
    from unitrack_env.datasets.davis import DAVISDataset

    root = DATA / "DAVIS"
    if not root.is_dir():
        pytest.skip("shared DAVIS fixture missing")
    seq = DAVISDataset(root, "val").load("blackswan")
    gt = np.stack([seq.read_annotation(i) for i in range(6)])
    perfect = vos.evaluate_vos_sequence(gt, gt, seq.object_ids, sequence_name=seq.name)
    assert perfect.j_and_f == 1.0
    shifted = np.roll(gt, (6, 9), axis=(1, 2))
    res = vos.evaluate_vos_sequence(gt, shifted, seq.object_ids, exclude_first_last=False)
    jandf, rle = _trackeval_jf()
    ref_f = jandf._compute_f([[rle(g == 1)] for g in gt], [[rle(s == 1)] for s in shifted],
                             0, 0, 0.008)
    np.testing.assert_allclose(res.f_per_frame[0], ref_f, atol=1e-12)
    assert 0.0 < res.summary["J-Mean"] < 1.0


@pytest.mark.filterwarnings(_PYCOCOTOOLS_NUMPY2)
def test_sequence_statistics_agree_with_trackeval_eval_sequence():
    # Two objects, no void, ids already aligned (TrackEval's Hungarian matching is then the
    # identity) and all frames kept: TrackEval's J&F must equal ours.
    jandf, rle = _trackeval_jf()
    rng = np.random.default_rng(1)
    t_len, shape = 7, (120, 160)
    gt = np.zeros((t_len, *shape), dtype=np.uint8)
    pred = np.zeros_like(gt)
    for t in range(t_len):
        gt[t, 20 + t : 60 + t, 30:80] = 1
        gt[t, 70:100, 90 + 2 * t : 130 + 2 * t] = 2
        dy, dx = rng.integers(-6, 7, size=2)
        pred[t] = np.roll(gt[t], (dy, dx), axis=(0, 1))
    pred[3][pred[3] == 2] = 0  # one miss
    ours = vos.evaluate_vos_sequence(gt, pred, (1, 2), exclude_first_last=False)
    ids = [np.array([0, 1])] * t_len
    data = {
        "num_timesteps": t_len, "num_tracker_ids": 2, "num_gt_ids": 2,
        "gt_ids": list(ids), "tracker_ids": list(ids),
        "gt_dets": [[rle(g == k) for k in (1, 2)] for g in gt],
        "tracker_dets": [[rle(p == k) for k in (1, 2)] for p in pred],
    }
    ref = jandf().eval_sequence(data)
    for key in ("J-Mean", "J-Recall", "J-Decay", "F-Mean", "F-Recall", "F-Decay", "J&F"):
        ours_key = "J&F-Mean" if key == "J&F" else key
        assert ours.summary[ours_key] == pytest.approx(ref[key], abs=1e-12), key
    assert 0.1 < ours.summary["F-Mean"] < 0.99  # a non-trivial case


# --------------------------------------------------------------------------- PCK


def test_normalisers_known_values():
    gt = np.array([[0.0, 0.0], [30.0, 40.0], [10.0, 10.0]])  # joint box 30 x 40
    assert pose.pck_normaliser(gt) == pytest.approx(0.6 * 50.0)
    assert pose.pck_normaliser(gt, "box_max_side") == pytest.approx(40.0)
    vis = np.array([True, False, True])  # box 10 x 10
    assert pose.pck_normaliser(gt, "box_max_side", vis) == pytest.approx(10.0)
    with pytest.raises(ValueError, match="box_diagonal"):
        pose.pck_normaliser(gt, "torso")  # type: ignore[arg-type]


def test_frame_pck_known_values():
    gt = np.array([[0.0, 0.0], [30.0, 40.0], [10.0, 10.0], [20.0, 20.0]])
    # normaliser 30 px -> alpha 0.1 is 3 px, alpha 0.2 is 6 px
    pred = gt + np.array([[2.9, 0.0], [0.0, 3.9], [5.0, 0.0], [0.0, 7.0]])
    assert pose.frame_pck(pred, gt, 0.1) == pytest.approx(1 / 4)
    assert pose.frame_pck(pred, gt, 0.2) == pytest.approx(3 / 4)
    assert pose.frame_pck(pred, gt, 0.1, "box_max_side") == pytest.approx(2 / 4)  # 4 px
    assert pose.frame_pck(gt, gt, 0.1) == 1.0


def test_pck_counts_skip_first_frame_and_average_over_joints():
    gt = np.zeros((3, 2, 2))
    gt[:, 1] = [30.0, 40.0]  # normaliser 30 px every frame
    pred = gt.copy()
    pred[0] += 100.0  # frame 0 is never scored
    pred[1, 0] += [5.0, 0.0]  # joint 0 wrong at 0.1 (5 > 3), right at 0.2 (5 <= 6)
    pred[2, 1] += [0.0, 10.0]  # joint 1 wrong at both thresholds
    counts = pose.pck_counts(pred, gt)
    assert counts.total.tolist() == [2, 2]
    assert counts.correct.tolist() == [[1, 1], [2, 1]]
    assert counts.as_dict() == pytest.approx({"PCK@0.1": 0.5, "PCK@0.2": 0.75})
    merged = counts.merge(pose.pck_counts(gt, gt))
    assert merged.as_dict() == pytest.approx({"PCK@0.1": 0.75, "PCK@0.2": 0.875})
    with pytest.raises(ValueError, match="merge"):
        counts.merge(pose.pck_counts(gt, gt, (0.1,)))


def test_pck_on_real_jhmdb_joints():
    from unitrack_env.datasets.jhmdb import JHMDBDataset

    root = DATA / "JHMDB"
    if not root.is_dir():
        pytest.skip("shared JHMDB fixture missing")
    seq = next(iter(JHMDBDataset(root)))
    gt = seq.keypoints
    assert pose.evaluate_pose_sequence(gt, gt) == {"PCK@0.1": 1.0, "PCK@0.2": 1.0}
    # Move every joint by 0.15 x its frame's normaliser: wrong at 0.1, right at 0.2.
    norm = pose.pck_normaliser(gt)
    pred = gt + np.stack([0.15 * norm, np.zeros_like(norm)], axis=1)[:, None, :]
    assert pose.evaluate_pose_sequence(pred, gt) == {"PCK@0.1": 0.0, "PCK@0.2": 1.0}
