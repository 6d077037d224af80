"""YouTube-VIS: JSON reader/writer, TrackEval track mAP on hand-made cases, env and goldens."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.datasets.rle import encode_masks
from unitrack_env.datasets.rle import mask_api as mask_utils
from unitrack_env.datasets.youtube_vis import (
    VisData,
    VisTrack,
    VisVideo,
    format_annotations,
    format_results,
    parse_vis_json,
    parse_vis_results,
    rle_to_json,
)
from unitrack_env.errors import DataFormatError, InvalidActionError
from unitrack_env.metrics.vis import merge_result_files, score_videos

GOLDENS = Path(__file__).resolve().parents[1] / "goldens"
H, W = 10, 12


def rle(x0, y0, x1, y1):
    mask = np.zeros((1, H, W), bool)
    mask[0, y0:y1, x0:x1] = True
    return {"size": [H, W], "counts": encode_masks(mask)[0]}


def dataset(tracks):
    video = VisVideo(7, "vid", ("vid/00000.jpg", "vid/00005.jpg"), H, W)
    return VisData(Path("gt.json"), (video,), {1: "person", 2: "dog"}, tuple(tracks)), video


# ------------------------------------------------------------------------ formats
def test_annotation_json_round_trip_with_polygons_and_uncompressed_rle(tmp_path):
    data, video = dataset([VisTrack(7, 1, (rle(0, 0, 4, 4), None), id=3),
                           VisTrack(7, 2, (rle(5, 5, 9, 9), rle(6, 5, 10, 9)), id=4)])
    text = format_annotations(data)
    raw = json.loads(text)
    assert raw["videos"][0]["file_names"] == ["vid/00000.jpg", "vid/00005.jpg"]
    ann = raw["annotations"][0]
    assert isinstance(ann["segmentations"][0]["counts"], list)  # uncompressed, as the 2019 files
    assert ann["segmentations"][1] is None and ann["areas"] == [16.0, None]
    assert ann["bboxes"][0] == [0.0, 0.0, 4.0, 4.0]
    back = parse_vis_json(tmp_path / "x.json", text=text)
    assert back.videos == data.videos and back.categories == data.categories
    for a, b in zip(back.tracks, data.tracks, strict=True):
        assert [s and s["counts"] for s in a.segmentations] == \
               [s and s["counts"] for s in b.segmentations]
    # A polygon covering the same square decodes to the same pixels.
    raw["annotations"][0]["segmentations"][0] = [[0, 0, 4, 0, 4, 4, 0, 4]]
    poly = parse_vis_json(tmp_path / "x.json", text=json.dumps(raw)).tracks[0].segmentations[0]
    iou = mask_utils.iou([poly], [rle(0, 0, 4, 4)], [False])[0, 0]
    assert iou > 0.5 and mask_utils.area(poly) > 0


def test_uncompressed_rle_runs_are_column_major_from_background():
    out = rle_to_json(rle(0, 0, 1, 2), uncompressed=True)  # pixels (0,0), (1,0): first column
    assert out == {"size": [H, W], "counts": [0, 2, H * W - 2]}


@pytest.mark.parametrize(("edit", "match"), [
    (lambda d: d["annotations"][0]["segmentations"].pop(), "annotations\\[0\\].segmentations"),
    (lambda d: d["annotations"][0].update(category_id=9), "unknown category 9"),
    (lambda d: d["videos"][0].pop("height"), "videos\\[0\\].height"),
    (lambda d: d["annotations"][0]["segmentations"].__setitem__(0, {"size": [1, 1],
                                                                    "counts": "0"}),
     "not the video's"),
])
def test_json_errors_name_the_json_path(edit, match):
    data, _ = dataset([VisTrack(7, 1, (rle(0, 0, 4, 4), None), id=1)])
    raw = json.loads(format_annotations(data))
    edit(raw)
    with pytest.raises(DataFormatError, match=match):
        parse_vis_json("gt.json", text=json.dumps(raw))


def test_invalid_json_reports_the_line():
    with pytest.raises(DataFormatError, match="line 2"):
        parse_vis_json("gt.json", text='{"videos": [],\n oops}')


def test_results_round_trip_and_skip_other_videos():
    data, video = dataset([])
    tracks = [VisTrack(7, 2, (None, rle(1, 1, 3, 3)), score=0.5),
              VisTrack(99, 1, (None,), score=0.9)]
    entries = json.loads(format_results(tracks))
    assert set(entries[0]) == {"video_id", "category_id", "segmentations", "score"}
    back = parse_vis_results(entries, {7: video})
    assert len(back) == 1 and back[0].category_id == 2 and back[0].score == 0.5
    assert back[0].segmentations[1]["counts"] == tracks[0].segmentations[1]["counts"]


# ------------------------------------------------------------------------ metric
def test_track_map_known_answers():
    a, b = rle(0, 0, 5, 5), rle(6, 0, 11, 5)
    data, video = dataset([VisTrack(7, 1, (a, a), id=1), VisTrack(7, 2, (b, b), id=2)])
    perfect = score_videos(data, [VisTrack(7, 1, (a, a), score=0.9),
                                  VisTrack(7, 2, (b, b), score=0.8)], [video])
    assert perfect.combined["AP"] == pytest.approx(1.0)
    assert perfect.per_sequence["vid"]["AP50"] == pytest.approx(1.0)
    # Person found on one of two frames: spatio-temporal IoU 25 / 50 = 0.5 -> only IoU 0.50
    # passes (AP 1 there, 0 at the nine stricter thresholds); the dog has the wrong class.
    half = score_videos(data, [VisTrack(7, 1, (a, None), score=0.9),
                               VisTrack(7, 1, (b, b), score=0.8)], [video])
    person_ap = 1 / 10
    assert half.combined["AP"] == pytest.approx(person_ap / 2)  # dog AP 0, classes averaged
    assert half.combined["AP50"] == pytest.approx(0.5) and half.combined["AP75"] == 0.0


# ------------------------------------------------------------------------ environment
def test_env_plays_scores_writes_and_rescores(tmp_path):
    from unitrack_env.agents import make_agent

    env = gym.make("UniTrack/VIS-v0")
    base = env.unwrapped
    agent = make_agent("iou")
    obs, info = env.reset(options={"sequence": "syn-02"})
    n = obs["num_detections"]
    assert obs["masks"].shape == (n, *info["image_size"]) and set(obs["classes"][:n]) <= {1, 2}
    agent.reset(obs, info)
    done = False
    while not done:
        obs, _, done, _, info = env.step(agent.act(obs))
    metrics = info["metrics"]
    assert 0.3 < metrics["AP"] <= 1.0 and metrics["AP50"] >= metrics["AP75"]
    base.write_episode(tmp_path)
    report = base.score_folder(tmp_path, ["syn-02"])
    assert report.per_sequence["syn-02"]["AP"] == pytest.approx(metrics["AP"])
    merged = merge_result_files(tmp_path)
    assert merged and {e["video_id"] for e in merged} == {info_id(base, "syn-02")}


def info_id(base, name):
    return base.dataset.video(name).id


def test_track_category_is_the_majority_class():
    env = gym.make("UniTrack/VIS-v0").unwrapped
    env.reset(options={"sequence": "syn-01"})
    env._tracks = {5: {0: ({"size": [1, 1], "counts": b"1"}, 2, 0.4),
                       1: ({"size": [1, 1], "counts": b"1"}, 1, 0.9),
                       2: ({"size": [1, 1], "counts": b"1"}, 2, 0.2)}}
    (track,) = env.episode_results()
    assert track.category_id == 2 and track.score == pytest.approx(0.5)
    assert track.segmentations[3] is None


def test_invalid_actions_and_valid_split_without_annotations():
    env = gym.make("UniTrack/VIS-v0").unwrapped
    obs, _ = env.reset(options={"sequence": "syn-01"})
    with pytest.raises(InvalidActionError):
        env.step({"ids": np.full(obs["num_detections"], 3)})
    test_env = gym.make("UniTrack/VIS-v0", split="valid", decode_frames=False)
    obs, info = test_env.reset()
    assert not info["has_ground_truth"]
    done = False
    while not done:
        obs, reward, done, _, info = test_env.step({"ids": np.zeros(0, np.int64)}
                                                   if not obs["num_detections"] else
                                                   {"ids": np.arange(1, obs["num_detections"] + 1)})
        assert reward == 0.0
    assert "metrics" not in info


def test_iou_golden_episode(episode_regression):
    episode_regression.check("UniTrack/VIS-v0", agent="iou", sequence="syn-01",
                             golden=GOLDENS / "iou-VIS-syn-01.json", tolerance=1e-9,
                             strict_actions=True)
