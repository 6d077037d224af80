"""The SOT protocols of LaSOT, UAV123 and GOT-10k: readers, envs, and parity with ``got10k``.

The ``got10k`` package (0.1.3, the parity reference of the test extra) implements the OTB,
UAV123 and GOT-10k protocols; its rate functions are called directly on the same boxes. It
has no LaSOT experiment: LaSOT's absent-frame rule is checked against the numbers its MATLAB
toolkit's ``calc_seq_err_robust.m`` / ``eval_tracker.m`` give by hand.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import unitrack_env  # noqa: F401 - registers the ids
from unitrack_env.benchmarks import benchmark_class, benchmark_for
from unitrack_env.datasets.lasot import LaSOTDataset
from unitrack_env.datasets.uav123 import UAV123Dataset
from unitrack_env.errors import DataFormatError
from unitrack_env.metrics.sot import (
    INVALID_GT_EXCLUDE,
    evaluate_sot_sequence,
    got10k_overlaps,
    got10k_scores,
)


def _reference_curves(experiment, pred, gt):
    """Success and precision curves as got10k's ``report`` computes them for one sequence."""
    runner = experiment.__new__(experiment)
    runner.nbins_iou, runner.nbins_ce = 21, 51
    pred = pred.copy()
    pred[0] = gt[0]
    ious, errors = runner._calc_metrics(pred, gt)
    return runner._calc_curves(ious, errors)


def _random_run(rng, gt, jitter=8.0):
    pred = gt + rng.normal(0, jitter, gt.shape)
    pred[:, 2:] = np.abs(pred[:, 2:]) + 1.0
    return pred


def _fixture_boxes(shared_data):
    lasot = LaSOTDataset(shared_data / "LaSOT").load("airplane-1").boxes
    uav = UAV123Dataset(shared_data / "UAV123").load("wakeboard7").boxes
    return {"airplane-1": lasot, "wakeboard7": uav}


def _synthetic_gt(rng, n=80):
    xy = 50 + np.cumsum(rng.normal(0, 3, (n, 2)), axis=0)
    wh = 30 + np.abs(rng.normal(0, 5, (n, 2)))
    return np.hstack([xy, wh])


def test_otb_curves_match_got10k_on_fixtures_and_synthetic(got10k_experiments, shared_data):
    rng = np.random.default_rng(0)
    cases = dict(_fixture_boxes(shared_data))
    cases["synthetic"] = _synthetic_gt(rng)
    for name, gt in cases.items():
        for pred in (_random_run(rng, gt), np.repeat(gt[:1], len(gt), axis=0)):
            ours = evaluate_sot_sequence(pred, gt)
            succ, prec = _reference_curves(got10k_experiments.ExperimentOTB, pred, gt)
            assert np.allclose(ours.success_curve, succ, atol=1e-6, rtol=0), name
            assert np.allclose(ours.precision_curve, prec, atol=1e-6, rtol=0), name
            assert abs(ours.auc - np.mean(succ)) < 1e-6
            assert abs(ours.precision_20px - prec[20]) < 1e-6


def test_uav123_absent_rows_match_got10k_when_excluded_and_the_toolkit_default_differs(
        got10k_experiments):
    rng = np.random.default_rng(1)
    gt = _synthetic_gt(rng)
    gt[[10, 11, 12, 40]] = np.nan  # UAV123's absent target
    pred = _random_run(rng, np.nan_to_num(gt, nan=40.0))
    succ, prec = _reference_curves(got10k_experiments.ExperimentUAV123, pred, gt)
    excluded = evaluate_sot_sequence(pred, gt, invalid_gt=INVALID_GT_EXCLUDE)
    assert np.allclose(excluded.success_curve, succ, atol=1e-6, rtol=0)
    assert np.allclose(excluded.precision_curve, prec, atol=1e-6, rtol=0)
    # The OTB toolkit's rule (UAV123's default here) keeps the 4 rows in the denominator:
    # they fail every success threshold and pass every precision threshold.
    default = evaluate_sot_sequence(pred, gt)
    n, valid = len(gt), len(gt) - 4
    assert np.allclose(default.success_curve, succ * valid / n, atol=1e-12)
    assert np.allclose(default.precision_curve, (prec * valid + 4) / n, atol=1e-12)


def test_got10k_ao_and_success_rates_match_got10k(got10k_experiments, shared_data):
    from got10k.utils.metrics import rect_iou

    rng = np.random.default_rng(2)
    runner = got10k_experiments.ExperimentGOT10k.__new__(got10k_experiments.ExperimentGOT10k)
    cases = dict(_fixture_boxes(shared_data))
    cases["synthetic"] = _synthetic_gt(rng)
    pooled_ours, pooled_ref = [], []
    for gt in cases.values():
        pred = _random_run(rng, gt, jitter=15.0)
        pred[::7, 0] -= 200  # some boxes leave the image: the bound clips them
        cover = rng.integers(0, 9, len(gt))
        ours = got10k_overlaps(pred, gt, cover, (640, 360))
        ref = rect_iou(pred[1:].copy(), gt[1:].copy(), bound=(640, 360))[cover[1:] > 0]
        assert np.allclose(ours, ref, atol=1e-6, rtol=0)
        pooled_ours.append(ours)
        pooled_ref.append(ref)
    ours = got10k_scores(np.concatenate(pooled_ours))
    ao, sr, _, curve = runner._evaluate(np.concatenate(pooled_ref), np.array([]))
    assert abs(ours["AO"] - ao) < 1e-6 and abs(ours["SR0.5"] - sr) < 1e-6
    assert abs(ours["SR0.75"] - curve[75]) < 1e-6


def test_lasot_absent_frames_fail_both_plots_but_stay_in_the_denominator():
    gt = np.tile([10.0, 10.0, 20.0, 20.0], (5, 1))
    pred = gt.copy()
    absent = np.array([False, False, True, True, False])
    scores = evaluate_sot_sequence(pred, gt, absent=absent, normalized=True)
    # eval_tracker.m: sum(err_coverage > thr) / len_all, absent rows removed first.
    assert scores.success_curve[0] == pytest.approx(3 / 5)
    assert scores.precision_20px == pytest.approx(3 / 5)
    assert scores.norm_precision == pytest.approx(3 / 5)
    assert scores.average_overlap == pytest.approx(1.0)  # over the frames it scores
    assert evaluate_sot_sequence(pred, gt).precision_20px == 1.0


def test_normalized_precision_divides_by_the_true_size():
    gt = np.array([[1.0, 1.0, 100.0, 10.0]] * 2)
    pred = gt + [[0, 0, 0, 0], [15.0, 1.5, 0, 0]]  # 0.15 and 0.15 normalized: 0.21
    scores = evaluate_sot_sequence(pred, gt, normalized=True)
    assert scores.norm_precision == pytest.approx(0.5)
    assert scores.precision_20px == 1.0


@pytest.mark.parametrize("env_id", ["UniTrack/LaSOT-v0", "UniTrack/UAV123-v0"])
def test_new_sot_ids_pass_check_env_on_their_synthetic_default_layout(env_id):
    env = gym.make(env_id)
    assert env.unwrapped.synthetic
    check_env(env.unwrapped, skip_render_check=True)
    observation, info = env.reset()
    terminated = False
    while not terminated:
        observation, _, terminated, _, info = env.step(observation["init_box"])
    assert {"AUC", "Precision@20px", "NormPrecision"} <= set(info["metrics"])
    env.close()
    assert type(benchmark_for(env_id)) is benchmark_class(env_id)


def test_synthetic_defaults_carry_absent_frames_and_lasot_nlp():
    lasot = benchmark_for("UniTrack/LaSOT-v0")
    assert lasot.sequence_names == ["walker-1", "walker-2"]  # testing_set.txt
    sequence = lasot.load("walker-1")
    assert sequence.absent.any() and sequence.description
    env = gym.make("UniTrack/LaSOT-v0")
    assert env.reset()[1]["nlp"] == sequence.description
    env.close()
    uav = benchmark_for("UniTrack/UAV123-v0", variant="10fps")
    seq = uav.load(uav.sequence_names[0])
    assert seq.benchmark == "UAV123_10fps" and np.isnan(seq.boxes).any(axis=1).any()
    assert seq.absent.tolist() == np.isnan(seq.boxes).any(axis=1).tolist()


def test_lasot_splits(tmp_path):
    from unitrack_env.datasets.lasot import write_synthetic_lasot

    write_synthetic_lasot(tmp_path)
    assert LaSOTDataset(tmp_path, "train").sequence_names == ["crosser-1"]
    assert LaSOTDataset(tmp_path, "ext").sequence_names == ["crosser-1", "walker-1", "walker-2"]
    split = tmp_path / "mine.txt"
    split.write_text("walker-2\n")
    assert LaSOTDataset(tmp_path, str(split)).sequence_names == ["walker-2"]
    (tmp_path / "training_set.txt").unlink()
    with pytest.raises(DataFormatError, match="training_set.txt"):
        LaSOTDataset(tmp_path, "train")
    with pytest.raises(ValueError, match="has no option 'variant'"):
        benchmark_for("UniTrack/LaSOT-v0", variant="10fps")


def test_bad_lasot_and_uav123_files_are_named_at_reset(tmp_path):
    from unitrack_env.datasets.lasot import write_synthetic_lasot
    from unitrack_env.datasets.uav123 import write_synthetic_uav123

    write_synthetic_lasot(tmp_path / "LaSOT")
    gt = tmp_path / "LaSOT" / "walker" / "walker-1" / "groundtruth.txt"
    good = gt.read_text()
    gt.write_text("NaN,1,2,3\n" + good.split("\n", 1)[1])
    env = gym.make("UniTrack/LaSOT-v0", root=str(tmp_path / "LaSOT"))
    with pytest.raises(DataFormatError, match=r"groundtruth.txt.*line 1.*first box"):
        env.reset()
    gt.write_text(good)
    flags = gt.parent / "full_occlusion.txt"
    flags.write_text("0,1\n")
    with pytest.raises(DataFormatError, match="full_occlusion.txt"):
        LaSOTDataset(tmp_path / "LaSOT").load("walker-1")
    write_synthetic_uav123(tmp_path / "UAV")
    anno = tmp_path / "UAV" / "anno" / "UAV123" / "synperson1.txt"
    anno.write_text("1,2,3,4\n")
    env = gym.make("UniTrack/UAV123-v0", root=str(tmp_path / "UAV"))
    with pytest.raises(DataFormatError, match="synperson1.txt.*1 rows but the frame folder"):
        env.reset()
    (tmp_path / "UAV" / "anno" / "UAV123" / "walker3_1.txt").write_text("1,2,3,4\n")
    with pytest.warns(UserWarning, match="walker3_1.*not among UAV123's"):
        UAV123Dataset(tmp_path / "UAV")


def test_real_fixtures_read_in_their_official_layouts(shared_data):
    lasot = LaSOTDataset(shared_data / "LaSOT").load("airplane-1")
    assert lasot.num_frames == 300 and lasot.description == "white airplane landing on ground"
    assert not lasot.absent.any()
    uav = UAV123Dataset(Path(shared_data) / "UAV123")
    assert uav.folder == "UAV123_10fps" and uav.load("wakeboard7").num_frames == 67


def test_rule_differences_measure_the_absent_frame_rules(tmp_path):
    from unitrack_env.benchmarks.otb import rule_differences

    bench = benchmark_for("UniTrack/LaSOT-v0")
    for name in bench.sequence_names:
        gt = bench.load(name).boxes
        bench.write(tmp_path, name, gt)  # a perfect tracker
    diff = rule_differences(bench, tmp_path, bench.sequence_names)
    absent = [bench.load(n).absent.mean() for n in bench.sequence_names]
    # The LaSOT toolkit fails a perfect tracker on every absent frame; excluding them does not.
    assert diff["excluded"]["Precision@20px"] == pytest.approx(1.0)
    assert diff["default"]["Precision@20px"] == pytest.approx(1 - np.mean(absent))
    assert diff["difference"]["AUC"] < 0


def test_got10k_id_plays_val_and_writes_the_servers_layout_for_test(tmp_path, got10k_experiments):
    from got10k.utils.metrics import rect_iou

    env = gym.make("UniTrack/GOT10k-v0")
    check_env(env.unwrapped, skip_render_check=True)
    observation, info = env.reset()
    terminated = False
    while not terminated:
        observation, _, terminated, _, info = env.step(observation["init_box"])
    assert set(info["metrics"]) == {"AO", "SR0.5", "SR0.75"}
    env.close()
    val = benchmark_for("UniTrack/GOT10k-v0")
    assert type(val) is benchmark_class("UniTrack/GOT10k-v0")
    rng = np.random.default_rng(3)
    pooled = []
    for name in val.sequence_names:
        sequence = val.load(name)
        for k in (1, 2):  # two repetitions, pooled like the toolkit
            run = _random_run(rng, sequence.boxes)
            path = tmp_path / name / f"{name}_{k:03d}.txt"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text("\n".join(",".join(map(str, r)) for r in run) + "\n")
            ref = rect_iou(run[1:].copy(), sequence.boxes[1:].copy(), bound=sequence.image_size)
            pooled.append(ref[~sequence.absent[1:]])
    report = val.score_files(tmp_path, val.sequence_names)
    assert report.combined["AO"] == pytest.approx(np.concatenate(pooled).mean(), abs=1e-6)
    test = benchmark_for("UniTrack/GOT10k-v0", split="test")
    name = test.sequence_names[0]
    assert not test.has_ground_truth(name)
    test.write(tmp_path / "submit", name, np.tile(test.load(name).init_box, (3, 1)))
    assert (tmp_path / "submit" / name / f"{name}_001.txt").is_file()


def test_bad_got10k_labels_are_named(tmp_path):
    from unitrack_env.datasets.lasot import GOT10kDataset, write_synthetic_got10k

    write_synthetic_got10k(tmp_path)
    cover = tmp_path / "val" / "GOT-10k_Val_000001" / "cover.label"
    cover.write_text("9\n" + cover.read_text().split("\n", 1)[1])
    with pytest.raises(DataFormatError, match=r"cover.label.*line 1.*0-8"):
        GOT10kDataset(tmp_path).load("GOT-10k_Val_000001")
    (tmp_path / "val" / "list.txt").write_text("GOT-10k_Val_000009\n")
    with pytest.raises(DataFormatError, match="list.txt.*GOT-10k_Val_000009"):
        GOT10kDataset(tmp_path)


def test_trackingnet_id_plays_train_and_test_writes_flat_submission(tmp_path):
    from unitrack_env.datasets.trackingnet import TrackingNetDataset, write_synthetic_trackingnet

    env = gym.make("UniTrack/TrackingNet-v0")
    check_env(env.unwrapped, skip_render_check=True)
    observation, info = env.reset()
    terminated = False
    while not terminated:
        observation, _, terminated, _, info = env.step(observation["init_box"])
    assert {"AUC", "Precision@20px", "NormPrecision"} <= set(info["metrics"])
    env.close()
    test = benchmark_for("UniTrack/TrackingNet-v0", split="test")
    assert test.sequence_names == ["syntest_0"] and not test.has_ground_truth("syntest_0")
    test.write(tmp_path / "submit", "syntest_0", np.tile(test.load("syntest_0").init_box, (24, 1)))
    assert (tmp_path / "submit" / "syntest_0.txt").is_file()
    write_synthetic_trackingnet(tmp_path / "TN")
    assert TrackingNetDataset(tmp_path / "TN", "TRAIN_1").sequence_names == ["synwalk_1"]
    (tmp_path / "TN" / "TRAIN_0" / "frames" / "synwalk_0" / "29.jpg").unlink()
    with pytest.raises(DataFormatError, match="synwalk_0.txt.*30 rows but the frame folder"):
        TrackingNetDataset(tmp_path / "TN").load("synwalk_0")
