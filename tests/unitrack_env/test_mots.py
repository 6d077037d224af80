"""MOTS: txt/png readers and writers, TrackEval adapter on hand-made cases, env and goldens."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.datasets.mots import MOTSDataset
from unitrack_env.datasets.mots_format import (
    MaskAnnotations,
    format_instances_txt,
    parse_instances_txt,
    read_instances_png,
    write_instances_png,
)
from unitrack_env.datasets.rle import decode_masks, encode_masks, resolve_overlaps
from unitrack_env.datasets.rle import mask_api as mask_utils
from unitrack_env.datasets.synthetic import ensure_synthetic
from unitrack_env.errors import DataFormatError, InvalidActionError
from unitrack_env.metrics.mots import MaskClearStream, mask_iou, score_sequence
from unitrack_env.spaces import MaskStack, mask_boxes, pack_mask_ids, unpack_mask_ids

GOLDENS = Path(__file__).resolve().parents[1] / "goldens"
H, W = 6, 8


def box_mask(x0, y0, x1, y1, shape=(H, W)):
    mask = np.zeros(shape, bool)
    mask[y0:y1, x0:x1] = True
    return mask


def records(rows, shape=(H, W)):
    """rows: (frame, id, class, mask) -> MaskAnnotations."""
    counts = encode_masks(np.stack([r[3] for r in rows])) if rows else []
    arr = np.array([r[:3] for r in rows], np.int64).reshape(-1, 3)
    n = len(rows)
    return MaskAnnotations(arr[:, 0], arr[:, 1], arr[:, 2], np.full(n, shape[0]),
                           np.full(n, shape[1]), tuple(counts), np.ones(n), np.zeros(n, np.int64))


# ------------------------------------------------------------------------ formats
def test_rle_round_trip_and_known_pycocotools_string():
    masks = np.stack([box_mask(1, 1, 3, 4), box_mask(5, 0, 8, 6), np.zeros((H, W), bool)])
    counts = encode_masks(masks)
    np.testing.assert_array_equal(decode_masks(counts, H, W), masks)
    # A 2x2 square at the top left of a 3x3 image: column-major runs 0,2,1,2,4; COCO's string
    # stores runs from the third on as differences to the run two before: 0,2,1,0,3.
    assert encode_masks(box_mask(0, 0, 2, 2, (3, 3))[None]) == [b"02103"]
    assert mask_utils.area({"size": [H, W], "counts": counts[0]}) == 6


def test_txt_round_trip_keeps_every_field(tmp_path):
    ann = records([(1, 2001, 2, box_mask(0, 0, 2, 2)), (1, 10000, 10, box_mask(4, 4, 6, 6)),
                   (3, 2002, 2, box_mask(1, 1, 5, 3))])
    path = tmp_path / "gt.txt"
    path.write_text(format_instances_txt(ann))
    back = parse_instances_txt(path)
    assert back.frames.tolist() == [1, 1, 3] and back.ids.tolist() == [2001, 10000, 2002]
    assert back.classes.tolist() == [2, 10, 2] and back.counts == ann.counts
    assert back.lines.tolist() == [1, 2, 3]
    first = path.read_text().splitlines()[0].split(" ")
    assert first[:5] == ["1", "2001", "2", str(H), str(W)]
    np.testing.assert_array_equal(back.decode(back.rows(3), H, W)[0], box_mask(1, 1, 5, 3))


@pytest.mark.parametrize(("line", "match"), [
    ("1 2001 2 6 8", "expected 6 space-separated fields"),
    ("1 2001 x 6 8 abc", "line 2, field 'class_id'"),
    ("1 2001 3 6 8 abc", "class 3 is not"),
    ("1 2001 2 0 8 abc", "must be positive"),
])
def test_txt_errors_name_file_line_and_field(tmp_path, line, match):
    path = tmp_path / "bad.txt"
    path.write_text(f"1 2001 2 6 8 724000g0\n{line}\n")  # a valid 6x8 RLE first
    with pytest.raises(DataFormatError, match=match) as info:
        parse_instances_txt(path)
    assert str(path) in str(info.value) and info.value.line == 2


def test_score_field_only_in_detection_files(tmp_path):
    path = tmp_path / "det.txt"
    path.write_text(f"1 -1 2 {H} {W} {encode_masks(box_mask(0, 0, 2, 2)[None])[0].decode()} 0.25\n")
    assert parse_instances_txt(path, allow_score=True).scores.tolist() == [0.25]
    with pytest.raises(DataFormatError, match="expected 6"):
        parse_instances_txt(path)


def test_png_variant_round_trips_through_the_txt_records(tmp_path):
    ann = records([(0, 2001, 2, box_mask(0, 0, 2, 2)), (0, 1003, 1, box_mask(3, 0, 8, 2)),
                   (0, 10000, 10, box_mask(0, 4, 8, 6)), (2, 2001, 2, box_mask(1, 1, 3, 3))])
    write_instances_png(tmp_path, ann, frames=[0, 1, 2], image_size=(H, W))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["000000.png", "000001.png", "000002.png"]
    back = read_instances_png(tmp_path)
    assert sorted(zip(back.frames.tolist(), back.ids.tolist(), back.classes.tolist(),
                      strict=True)) == [
        (0, 1003, 1), (0, 2001, 2), (0, 10000, 10), (2, 2001, 2)]
    for t, obj in ((0, 1003), (2, 2001)):
        i = next(i for i in range(len(back)) if back.frames[i] == t and back.ids[i] == obj)
        j = next(j for j in range(len(ann)) if ann.frames[j] == t and ann.ids[j] == obj)
        assert back.counts[i] == ann.counts[j]


def test_synthetic_kitti_layout_png_equals_txt_and_frames_are_zero_based():
    root = ensure_synthetic("KITTI-MOTS", kind="mots")
    data = MOTSDataset(root, "KITTI-MOTS", "training")
    info = data.info("SYN-01")
    assert info.first_frame == 0 and info.frame_path(0).name == "000000.png"
    txt = parse_instances_txt(root / "instances_txt" / "SYN-01.txt")
    png = read_instances_png(root / "instances" / "SYN-01")
    key = lambda a: sorted(zip(a.frames.tolist(), a.ids.tolist(), a.counts, strict=True))  # noqa: E731
    assert key(txt) == key(png) and txt.frames.min() == 0
    assert MOTSDataset(root, "KITTI-MOTS", "testing").ground_truth("SYN-03") is None


def test_overlaps_go_to_the_higher_score():
    a, b = box_mask(0, 0, 4, 4), box_mask(2, 2, 6, 6)
    out = resolve_overlaps(np.stack([a, b]), np.array([0.3, 0.9]))
    assert out[1].sum() == 16 and out[0].sum() == 12 and not (out[0] & out[1]).any()


# ------------------------------------------------------------------------ spaces
def test_mask_stack_space_and_id_actions():
    space = MaskStack(3, 10, 10)
    assert space.contains(np.zeros((2, 4, 5), bool))
    assert not space.contains(np.zeros((4, 4, 5), bool))  # too many
    assert not space.contains(np.zeros((2, 4, 5), np.uint8))  # dtype
    assert mask_boxes(box_mask(1, 2, 4, 3)[None]).tolist() == [[1, 2, 3, 1]]
    assert unpack_mask_ids(pack_mask_ids([5, 0], 4), 2, 4).tolist() == [5, 0]
    assert unpack_mask_ids({"ids": [7]}, 1, 4).tolist() == [7]
    with pytest.raises(InvalidActionError, match="has 3 entries"):
        unpack_mask_ids({"ids": [1, 2, 3]}, 2, 4)
    with pytest.raises(InvalidActionError, match="several detections"):
        unpack_mask_ids({"ids": [4, 4]}, 2, 4)
    with pytest.raises(InvalidActionError, match=">= 1"):
        unpack_mask_ids({"ids": [-1, 2]}, 2, 4)


# ------------------------------------------------------------------------ metrics
def test_trackeval_perfect_and_switch_cases():
    p1, p2 = box_mask(0, 0, 3, 4), box_mask(4, 0, 8, 4)
    gt = records([(1, 2001, 2, p1), (1, 2002, 2, p2), (2, 2001, 2, p1), (2, 2002, 2, p2)])
    perfect = score_sequence(gt, records([(1, 5, 2, p1), (1, 6, 2, p2), (2, 5, 2, p1),
                                          (2, 6, 2, p2)]), seq_length=2)
    assert perfect["MOTSA"] == 1 and perfect["sMOTSA"] == 1 and perfect["IDF1"] == 1
    assert perfect["HOTA"] == pytest.approx(1.0)
    switched = score_sequence(gt, records([(1, 5, 2, p1), (1, 6, 2, p2), (2, 6, 2, p1),
                                           (2, 5, 2, p2)]), seq_length=2)
    assert switched["IDSW"] == 2 and switched["MOTSA"] == pytest.approx((4 - 0 - 2) / 4)
    assert switched["IDF1"] == pytest.approx(0.5)


def test_trackeval_soft_match_ignore_region_and_false_positive():
    gt_mask, ignore = box_mask(0, 0, 4, 5), box_mask(6, 0, 8, 6)
    gt = records([(1, 2001, 2, gt_mask), (1, 10000, 10, ignore)])
    partial = box_mask(0, 0, 4, 3)  # IoU 12 / 20 = 0.6: a match, counted softly in sMOTSA
    inside = box_mask(6, 0, 8, 3)  # fully inside the ignore region: dropped
    free = box_mask(4, 5, 6, 6)  # a false positive
    score = score_sequence(gt, records([(1, 1, 2, partial), (1, 2, 2, inside), (1, 3, 2, free)]),
                           seq_length=1)
    assert score["CLR_TP"] == 1 and score["CLR_FP"] == 1
    assert score["MOTSA"] == pytest.approx(0.0) and score["sMOTSA"] == pytest.approx(0.6 - 1)
    assert score["MOTSP"] == pytest.approx(0.6)


def test_an_ignore_region_over_two_rows_is_one_region(tmp_path):
    """TrackEval merges the rows of id 10000 in a frame; so do the checks and the stream."""
    from unitrack_env.datasets.mots import MOTSSequenceInfo, check_ground_truth

    person = (1, 2001, 2, box_mask(0, 0, 4, 5))
    split = records([person, (1, 10000, 10, box_mask(6, 0, 8, 3)),
                     (1, 10000, 10, box_mask(6, 3, 8, 6))])
    whole = records([person, (1, 10000, 10, box_mask(6, 0, 8, 6))])
    check_ground_truth(split, MOTSSequenceInfo("S", tmp_path, 1, 1, W, H, 30.0, ".jpg"))
    res = records([(1, 1, 2, box_mask(0, 0, 4, 5)), (1, 2, 2, box_mask(6, 1, 8, 5))])
    assert score_sequence(split, res, seq_length=1) == score_sequence(whole, res, seq_length=1)
    stream = MaskClearStream()
    stream.reset()
    g, r = split.rows(1), res.rows(1)
    keep = split.classes[g] == 2
    stream.update(split.ids[g][keep], split.rles(g[keep]), split.rles(g[~keep]), res.ids[r],
                  res.rles(r))
    assert (stream.totals.tp, stream.totals.fp) == (1, 0)  # the second mask is ignored


def test_streaming_counts_match_trackeval_on_the_same_frames():
    p1, p2 = box_mask(0, 0, 3, 4), box_mask(4, 0, 8, 4)
    ign = box_mask(0, 5, 8, 6)
    stream = MaskClearStream()
    stream.reset()
    gt = records([(1, 2001, 2, p1), (1, 2002, 2, p2), (2, 2001, 2, p1), (2, 10000, 10, ign)])
    res = records([(1, 5, 2, p1), (2, 6, 2, p1), (2, 7, 2, ign), (2, 8, 2, p2)])
    for t in (1, 2):
        g, r = gt.rows(t), res.rows(t)
        keep = gt.classes[g] == 2
        stream.update(gt.ids[g][keep], gt.rles(g[keep]), gt.rles(g[~keep]), res.ids[r],
                      res.rles(r))
    official = score_sequence(gt, res, seq_length=2)
    totals = stream.totals
    assert (totals.tp, totals.fp, totals.fn, totals.idsw) == (
        official["CLR_TP"], official["CLR_FP"], official["CLR_FN"], official["IDSW"])
    assert mask_iou(gt.rles([0]), res.rles([0]))[0, 0] == 1.0


def test_overlapping_results_are_rejected_with_the_file_named(tmp_path):
    gt = records([(1, 2001, 2, box_mask(0, 0, 3, 3))])
    path = tmp_path / "seq.txt"
    path.write_text(format_instances_txt(records([(1, 1, 2, box_mask(0, 0, 3, 3)),
                                                  (1, 2, 2, box_mask(2, 2, 4, 4))])))
    with pytest.raises(DataFormatError, match="overlapping masks") as info:
        score_sequence(gt, path, seq_length=1)
    assert str(path) in str(info.value)


# ------------------------------------------------------------------------ environment
def test_env_reward_sums_to_motsa_and_results_round_trip(tmp_path):
    from unitrack_env.agents import make_agent

    env = gym.make("UniTrack/MOTS-v0")
    agent = make_agent("iou")
    obs, info = env.reset(options={"sequence": "SYN-02"})
    assert obs["masks"].shape == (obs["num_detections"], *info["image_size"])
    agent.reset(obs, info)
    total, done = 0.0, False
    while not done:
        obs, reward, done, _, info = env.step(agent.act(obs))
        total += reward
    m = info["metrics"]
    assert total / (m["CLR_TP"] + m["CLR_FN"]) == pytest.approx(m["MOTSA"])
    base = env.unwrapped
    base.write_episode(tmp_path)
    report = base.score_folder(tmp_path, ["SYN-02"])
    assert report.per_sequence["SYN-02"]["HOTA"] == pytest.approx(m["HOTA"])
    assert m["MOTSA"] > 0.7 and m["IDSW"] <= 5  # the IoU baseline tracks the synthetic people


def test_env_rejects_bad_actions_before_recording():
    env = gym.make("UniTrack/MOTS-v0").unwrapped
    obs, _ = env.reset(options={"sequence": "SYN-01"})
    n = obs["num_detections"]
    assert n >= 2
    with pytest.raises(InvalidActionError):
        env.step({"ids": np.ones(n, np.int64)})  # one id on two masks
    with pytest.raises(InvalidActionError):
        env.step({"ids": np.arange(1, n + 2)})  # wrong length
    assert env.episode_results().frames.size == 0


def test_test_split_runs_without_ground_truth(tmp_path):
    env = gym.make("UniTrack/MOTS-v0", split="test")
    obs, info = env.reset()
    assert not info["has_ground_truth"]
    done = False
    while not done:
        obs, reward, done, _, info = env.step({"ids": np.arange(1, obs["num_detections"] + 1)})
        assert reward == 0.0
    assert "metrics" not in info
    env.unwrapped.write_episode(tmp_path)
    assert (tmp_path / "SYN-03.txt").read_text().startswith("1 ")


def test_kitti_layout_and_gt_detections_give_a_perfect_oracle():
    env = gym.make("UniTrack/MOTS-v0", benchmark="KITTI-MOTS", detections="gt",
                   decode_frames=False)
    obs, info = env.reset(options={"sequence": "SYN-02"})
    assert info["frame_index"] == 0 and info["frame_rate"] == 10.0
    done = False
    while not done:  # gt masks as detections; give each its gt id: the result is the gt
        rows = env.unwrapped._dets.rows(info["frame_index"])
        obs, _, done, _, info = env.step({"ids": env.unwrapped._dets.ids[rows]})
    assert info["metrics"]["MOTSA"] == 1.0 and info["metrics"]["IDF1"] == 1.0


def test_missing_detections_explain_the_options(tmp_path):
    with pytest.raises(DataFormatError, match="detections='gt'"):
        gym.make("UniTrack/MOTS-v0", detections=tmp_path).reset()


def test_iou_golden_episode(episode_regression):
    episode_regression.check("UniTrack/MOTS-v0", agent="iou", sequence="SYN-01",
                             golden=GOLDENS / "iou-MOTS-SYN-01.json", tolerance=1e-9,
                             strict_actions=True)
