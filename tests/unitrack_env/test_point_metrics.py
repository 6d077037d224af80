"""TAP-Vid metrics and query sampling: hand-built cases with known answers, and a rescoring
of written results by a second, deliberately simple implementation of the paper's
definitions (loops over queries and frames, nothing shared with the library)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from unitrack_env.metrics.point_queries import episode_schedule, sample_queries, to_raster
from unitrack_env.metrics.points import (
    evaluated_pairs,
    event_rows,
    frame_values,
    mean_over_videos,
    video_metrics,
)

# One query at frame 0 of a 4-frame video: the point sits at (10, 10), visible in frames
# 0-2, occluded in frame 3. The prediction is 0.5 px off in frame 1, 3 px off in frame 2 and
# says "visible" everywhere.
GT = np.array([[[10.0, 10.0]] * 4])
GT_OCC = np.array([[False, False, False, True]])
PRED = np.array([[[10.0, 10.0], [10.5, 10.0], [13.0, 10.0], [50.0, 50.0]]])
PRED_OCC = np.zeros((1, 4), bool)


def test_hand_built_first_mode():
    m = video_metrics(np.array([[0, 10, 10]]), GT, GT_OCC, PRED, PRED_OCC, "first")
    # evaluated: frames 1, 2, 3; flags right in 1 and 2
    assert m["OA"] == pytest.approx(2 / 3)
    # visible evaluated: frames 1 (0.5 px) and 2 (3 px)
    assert [m[f"delta_x@{d}"] for d in (1, 2, 4, 8, 16)] == [0.5, 0.5, 1, 1, 1]
    assert m["delta_x_avg"] == pytest.approx(0.8)
    # d < 3: TP 1, FP 2 (frame 2 too far, frame 3 occluded) -> 1 / (2 + 2)
    # d > 3: TP 2, FP 1 (frame 3) -> 2 / (2 + 1)
    assert m["Jaccard@1"] == m["Jaccard@2"] == pytest.approx(0.25)
    assert m["Jaccard@4"] == m["Jaccard@16"] == pytest.approx(2 / 3)
    assert m["AJ"] == pytest.approx((0.25 * 2 + 2 / 3 * 3) / 5)


def test_hand_built_strided_mode_scores_frames_before_the_query():
    # the same track asked at frame 2: frames 0, 1, 3 are evaluated, frame 2 is not
    m = video_metrics(np.array([[2, 10, 10]]), GT, GT_OCC, PRED, PRED_OCC, "strided")
    assert m["OA"] == pytest.approx(2 / 3)
    assert m["delta_x@1"] == 1.0  # frames 0 and 1 within 1 px; frame 2 (3 px off) not scored
    assert m["Jaccard@1"] == pytest.approx(2 / 3)  # TP 2, FP 1 (frame 3)


def test_threshold_is_strict_and_flags_do_not_matter_for_delta():
    pred = GT.copy()
    pred[0, 1] += [4.0, 0.0]  # exactly 4 px: not within 4, within 8
    occ = np.array([[False, True, False, True]])  # frame 1 predicted occluded
    m = video_metrics(np.array([[0, 10, 10]]), GT, GT_OCC, pred, occ, "first")
    assert m["delta_x@4"] == 0.5 and m["delta_x@8"] == 1.0
    # frame 1 is a false negative at every threshold: TP 1 (frame 2), FN 1, FP 0
    assert m["Jaccard@16"] == pytest.approx(0.5)
    assert m["OA"] == pytest.approx(2 / 3)


def test_an_undefined_ratio_is_nan_and_left_out_of_the_mean():
    occluded = np.array([[False, True, True, True]])  # never visible after the query
    nothing = video_metrics(np.array([[0, 10, 10]]), GT, occluded, PRED, PRED_OCC, "first")
    assert math.isnan(nothing["delta_x_avg"])  # no visible pair: 0 / 0
    assert nothing["AJ"] == 0.0 and nothing["OA"] == 0.0  # three false positives
    good = video_metrics(np.array([[0, 10, 10]]), GT, GT_OCC, GT, GT_OCC, "first")
    assert good["AJ"] == good["delta_x_avg"] == 1.0
    mean = mean_over_videos({"a": nothing, "b": good})
    assert mean["delta_x_avg"] == 1.0 and mean["AJ"] == 0.5 and mean["OA"] == 0.5


def test_sampling_first_and_strided_follow_the_reference_order():
    occ = np.ones((3, 12), bool)
    occ[0, 3:] = False  # track 0 from frame 3
    occ[1, :] = False  # track 1 always
    occ[2, 5:7] = False  # track 2 at frames 5, 6 only
    xy = np.random.default_rng(0).uniform(0, 1, (3, 12, 2))
    first = sample_queries(xy, occ, "first")
    assert first.query_frames.tolist() == [3, 0, 5]
    assert first.track_index.tolist() == [0, 1, 2]
    assert first.query_points[0].tolist() == [3.0, xy[0, 3, 1], xy[0, 3, 0]]
    strided = sample_queries(xy, occ, "strided")
    # q = 0: track 1; q = 5: tracks 0, 1, 2; q = 10: tracks 0, 1
    assert list(zip(strided.query_frames.tolist(), strided.track_index.tolist(),
                    strict=True)) == \
        [(0, 1), (5, 0), (5, 1), (5, 2), (10, 0), (10, 1)]
    assert np.array_equal(strided.occluded, occ[strided.track_index])
    assert to_raster([[0.5, 0.25]], (256, 128)).tolist() == [[128.0, 32.0]]


def test_schedule_adds_a_reversed_pass_only_for_strided_queries_after_frame_0():
    assert episode_schedule(3, np.array([0, 1]), "first") == [(0, False), (1, False),
                                                              (2, False)]
    assert episode_schedule(2, np.array([0]), "strided") == [(0, False), (1, False)]
    assert episode_schedule(3, np.array([0, 1]), "strided")[3:] == [(1, True), (0, True)]


def test_frame_values_and_event_rows_agree_with_the_video_metrics():
    evaluated = evaluated_pairs(np.array([0]), 4, "first")
    values = frame_values(PRED, PRED_OCC, GT, GT_OCC, evaluated)
    assert math.isnan(values["AJ"][0])  # the query frame is not scored
    assert values["delta_x_avg"][1] == 1.0 and values["delta_x_avg"][2] == 0.6
    assert values["OA"].tolist()[1:] == [1.0, 1.0, 0.0]
    rows = event_rows(PRED, PRED_OCC, GT, GT_OCC, evaluated)
    assert [(r["frame"], r["within"], r["occlusion_correct"]) for r in rows] == \
        [(1, 1, True), (2, 4, True), (3, 0, False)]
    assert rows[2]["error_px"] is None and rows[1]["error_px"] == 3.0


# ---------------------------------------------------------------- the second implementation
def simple_tapvid_metrics(query_points, gt_tracks, gt_occluded, tracks, occluded, mode):
    """The paper's definitions, written as plainly as possible (an independent check)."""
    totals = {"pairs": 0, "flags_right": 0, "visible": 0}
    for d in (1, 2, 4, 8, 16):
        totals[("near", d)] = totals[("tp", d)] = totals[("fp", d)] = 0
    for i in range(len(query_points)):
        q = int(round(query_points[i][0]))
        for t in range(gt_tracks.shape[1]):
            if t == q or (mode == "first" and t < q):
                continue
            totals["pairs"] += 1
            gt_visible = not gt_occluded[i][t]
            said_visible = not occluded[i][t]
            totals["flags_right"] += gt_visible == said_visible
            dx = float(tracks[i][t][0]) - float(gt_tracks[i][t][0])
            dy = float(tracks[i][t][1]) - float(gt_tracks[i][t][1])
            distance = math.sqrt(dx * dx + dy * dy)
            totals["visible"] += gt_visible
            for d in (1, 2, 4, 8, 16):
                near = gt_visible and distance < d
                totals[("near", d)] += near
                totals[("tp", d)] += near and said_visible
                totals[("fp", d)] += said_visible and not near
    jaccards = [totals[("tp", d)] / (totals["visible"] + totals[("fp", d)])
                for d in (1, 2, 4, 8, 16)]
    deltas = [totals[("near", d)] / totals["visible"] for d in (1, 2, 4, 8, 16)]
    return {"AJ": sum(jaccards) / 5, "delta_x_avg": sum(deltas) / 5,
            "OA": totals["flags_right"] / totals["pairs"]}


@pytest.mark.parametrize("mode", ["first", "strided"])
def test_written_results_rescored_independently(tmp_path, mode):
    """Play a noisy agent, write the .npz files, rescore them with the simple version."""
    import gymnasium as gym

    import unitrack_env  # noqa: F401

    env = gym.make("UniTrack/TAPVid-DAVIS-v0", query_mode=mode).unwrapped
    rng = np.random.default_rng(1)
    per_video = {}
    for name in env.sequence_names:
        observation, info = env.reset(options={"sequence": name})
        truth = env.scoring.queries(name)
        terminated = False
        while not terminated:
            frame = info["frame_index"]
            guess = truth.tracks[:, frame] + rng.normal(0, 3, truth.tracks[:, frame].shape)
            flags = truth.occluded[:, frame] ^ (rng.uniform(size=len(truth)) < 0.2)
            observation, _, terminated, _, info = env.step({"tracks": guess, "occluded": flags})
        env.write_episode(tmp_path)
        per_video[name] = info["metrics"]
    report = env.scoring.score_folder(tmp_path)
    for name in env.sequence_names:
        with np.load(tmp_path / f"{name}.npz", allow_pickle=False) as files:
            video = env.scoring.load(name)
            gt = sample_queries(video.points * 256.0, video.occluded, mode)
            simple = simple_tapvid_metrics(files["query_points"], gt.tracks, gt.occluded,
                                           files["tracks"], files["occluded"], mode)
        for key, value in simple.items():
            assert report.per_sequence[name][key] == pytest.approx(value, abs=1e-6)
            assert per_video[name][key] == pytest.approx(value, abs=1e-6)
    for key in ("AJ", "delta_x_avg", "OA"):
        assert report.combined[key] == pytest.approx(
            np.mean([report.per_sequence[n][key] for n in env.sequence_names]), abs=1e-12)
