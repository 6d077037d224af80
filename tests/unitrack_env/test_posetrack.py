"""PoseTrack 2018: JSON reader/writer, poseval metrics (known answers + motmetrics), episodes."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.datasets.posetrack import PoseTrackDataset
from unitrack_env.datasets.posetrack_json import (
    parse_posetrack,
    read_posetrack_json,
    video_to_json,
    write_posetrack_json,
)
from unitrack_env.datasets.posetrack_records import (
    NUM_KEYPOINTS,
    POSETRACK_KEYPOINTS,
    PoseTrackImage,
    PoseTrackPerson,
    PoseTrackVideo,
)
from unitrack_env.datasets.synthetic.posetrack import labeled_frames
from unitrack_env.errors import DataFormatError, InvalidActionError
from unitrack_env.metrics.posetrack import (
    PosevalSequence,
    SequenceCounts,
    evaluate_video,
    summarise,
)
from unitrack_env.metrics.posetrack_frames import NUM_JOINTS, POSEVAL_JOINTS, PoseFrame
from unitrack_env.metrics.posetrack_joint import ClearAccumulator
from unitrack_env.spaces import pack_pose_tracks, unpack_poses

HEAD = np.array([[0.0, 0.0, 30.0, 40.0]])  # diagonal 50 -> head size 30 -> threshold 15 px


def _pose(x0: float = 100.0, y0: float = 100.0) -> np.ndarray:
    """A full 17-keypoint pose (ears unannotated), one keypoint every 10 px."""
    kp = np.zeros((NUM_KEYPOINTS, 3))
    kp[:, 0] = x0 + 10.0 * np.arange(NUM_KEYPOINTS)
    kp[:, 1] = y0
    kp[:, 2] = 1.0
    kp[3:5] = 0.0
    return kp


def _frame(ids, poses, heads=None) -> PoseFrame:
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, NUM_KEYPOINTS, 3)
    heads = None if heads is None else np.repeat(HEAD, len(poses), axis=0)
    return PoseFrame.from_keypoints(ids, poses, heads)


# ----------------------------------------------------------------------------- reader
def test_real_files_round_trip_exactly(shared_data):
    folder = shared_data / "PoseTrack2018" / "posetrack_data" / "annotations" / "val"
    files = sorted(folder.glob("*.json"))
    assert len(files) == 2
    for path in files:
        original = json.loads(path.read_text())
        video = read_posetrack_json(path)
        assert video_to_json(video) == original
        assert len(video.images) == 1 and video.images[0].nframes in (149, 140)
        assert video.images[0].ignore_regions  # the crowd polygons are parsed
    video = read_posetrack_json(folder / "012834_mpii_test.json")
    first = video.people[0][0]
    assert first.track_id == 0 and first.bbox_head == (378.0, 503.0, 44.0, 53.0)
    assert first.keypoints[0].tolist() == [401.0, 530.0, 1.0]
    assert not first.annotated[3] and first.annotated.sum() == 11  # num_keypoints in the file


def test_writer_round_trip(tmp_path):
    image = PoseTrackImage(id=10000010000, file_name="images/val/000001_x/000000.jpg",
                           is_labeled=True, nframes=1, frame_id=10000010000, vid_id="000001",
                           ignore_regions=(np.array([[0, 0], [5, 0], [5, 5.5]]),))
    person = PoseTrackPerson(image_id=image.id, keypoints=_pose(), track_id=3,
                             scores=np.linspace(0, 1, NUM_KEYPOINTS), score=0.5,
                             bbox_head=(1.0, 2.0, 3.0, 4.5), extra={"category_id": 1})
    path = tmp_path / "000001_x.json"
    write_posetrack_json(path, PoseTrackVideo([image], [[person]]))
    back = read_posetrack_json(path)
    assert video_to_json(back) == json.loads(path.read_text())
    np.testing.assert_array_equal(back.people[0][0].keypoints, person.keypoints)
    np.testing.assert_array_equal(back.people[0][0].scores, person.scores)
    np.testing.assert_array_equal(back.images[0].ignore_regions[0], image.ignore_regions[0])
    assert back.categories[0]["keypoints"] == list(POSETRACK_KEYPOINTS)


@pytest.mark.parametrize(
    ("mutate", "field"),
    [
        (lambda d: d["annotations"][0].pop("keypoints"), "annotations[0].keypoints"),
        (lambda d: d["annotations"][0].update(keypoints=[1, 2, 3]), "annotations[0].keypoints"),
        (lambda d: d["annotations"][0].update(image_id=7), "annotations[0].image_id"),
        (lambda d: d["images"][0].pop("file_name"), "images[0].file_name"),
        (lambda d: d["categories"][0].update(keypoints=["a"] * 17), "categories[0].keypoints"),
    ],
)
def test_reader_names_the_bad_field(mutate, field):
    data = {"images": [{"id": 1, "file_name": "images/val/s/000000.jpg"}],
            "annotations": [{"image_id": 1, "keypoints": _pose().reshape(-1).tolist()}],
            "categories": [{"name": "person", "keypoints": list(POSETRACK_KEYPOINTS)}]}
    parse_posetrack(data)
    mutate(data)
    with pytest.raises(DataFormatError, match=field.replace("[", r"\[").replace("]", r"\]")):
        parse_posetrack(data, "x.json")


# ----------------------------------------------------------------------------- metrics
def test_perfect_tracking_scores_one():
    seq = PosevalSequence()
    for _ in range(3):
        counts = seq.update(_frame([1, 2], [_pose(), _pose(0, 300)], HEAD),
                            _frame([7, 8], [_pose(), _pose(0, 300)]))
        assert counts.mota_numerator == 2 * NUM_JOINTS
    m = summarise([seq.counts()])
    assert m["MOTA"] == m["IDF1"] == m["Precision"] == m["Recall"] == 1.0
    assert m["IDSW"] == 0 and m["MOTP"] == 1.0 and m["num_objects"] == 3 * 2 * NUM_JOINTS


def test_threshold_is_half_the_head_size():
    gt = _frame([1], [_pose()], HEAD)  # head size 0.6 * 50 = 30 px -> match within 15 px
    inside, outside = _pose(), _pose()
    inside[:, 0] += 15.0
    outside[:, 0] += 15.01
    inside[3:5], outside[3:5] = 0.0, 0.0
    a = PosevalSequence()
    a.update(gt, _frame([1], [inside]))
    b = PosevalSequence()
    b.update(gt, _frame([1], [outside]))
    ca, cb = a.counts(), b.counts()
    assert ca.matches.tolist() == [1] * NUM_JOINTS and ca.distance[0] == pytest.approx(0.5)
    assert cb.misses.tolist() == [1] * NUM_JOINTS and cb.false_positives.tolist() == [1] * 15
    assert summarise([ca])["MOTP"] == pytest.approx(0.5)
    assert summarise([cb])["MOTA"] == -1.0


def test_motp_of_a_joint_without_detections_is_zero_as_in_poseval():
    """poseval sets a joint's MOTP to 0 when it has no detections and averages those zeros
    with the rest, so a sequence can score lower than the pooled set (seen on PoseTrack:
    one sequence 66.7, combined 100)."""
    zeros = np.zeros(NUM_JOINTS)
    seen = np.arange(NUM_JOINTS) < 10  # joints 0-9 detected (distance 0), 10-14 only missed
    first = SequenceCounts(matches=seen * 1.0, switches=zeros, misses=(~seen) * 1.0,
                           false_positives=zeros, distance=zeros, idf1=zeros, frames=1)
    second = SequenceCounts(matches=np.ones(NUM_JOINTS), switches=zeros, misses=zeros,
                            false_positives=zeros, distance=zeros, idf1=zeros, frames=1)
    assert summarise([first])["MOTP"] == pytest.approx(10 / 15)
    assert summarise([first, second])["MOTP"] == 1.0


def test_id_switch_counts_per_joint_and_sums():
    seq = PosevalSequence()
    seq.update(_frame([1], [_pose()], HEAD), _frame([5], [_pose()]))
    seq.update(_frame([1], [_pose()], HEAD), _frame([6], [_pose()]))
    m = summarise([seq.counts()])
    assert m["IDSW"] == NUM_JOINTS  # one switch per joint, summed over joints
    assert m["IDSW/head_top"] == 1.0
    assert m["MOTA"] == pytest.approx(0.5)  # per joint: 1 - 1 switch / 2 objects
    assert m["IDF1"] == pytest.approx(0.5)  # best id mapping covers 1 of 2 frames


def test_previous_match_is_kept_over_a_closer_pose():
    """py-motmetrics keeps last frame's pair while it is a candidate, even if not optimal."""
    seq = PosevalSequence()
    seq.update(_frame([1], [_pose()], HEAD), _frame([5], [_pose()]))
    near, far = _pose(), _pose()
    far[:, 0] += 10.0
    far[3:5] = 0.0
    counts = seq.update(_frame([1], [_pose()], HEAD), _frame([6, 5], [near, far]))
    assert counts.switches.sum() == 0 and counts.false_positives.tolist() == [1] * NUM_JOINTS


def test_frame_without_predictions_is_one_dummy_miss_and_false_positive():
    seq = PosevalSequence()
    counts = seq.update(_frame([1, 2, 3], [_pose(), _pose(0, 200), _pose(0, 300)], HEAD),
                        PoseFrame.empty())
    assert counts.misses.tolist() == [1] * NUM_JOINTS  # not 3: poseval's dummy entry
    assert counts.false_positives.tolist() == [1] * NUM_JOINTS
    assert summarise([seq.counts()])["MOTA"] == -1.0


def test_ignore_regions_remove_keypoints_of_both_sides():
    region = np.array([[95.0, 90.0], [125.0, 90.0], [125.0, 110.0], [95.0, 110.0]])
    pred = _pose()
    pred[:, 0] += 200.0  # all wrong ...
    pred[:3] = _pose()[:3]  # ... except nose, head_bottom, head_top (x 100..120)
    seq = PosevalSequence()
    seq.update(_frame([1], [_pose()], HEAD), _frame([1], [pred]), (region,))
    counts = seq.counts()
    head = [POSEVAL_JOINTS.index(n) for n in ("nose", "head_bottom", "head_top")]
    assert counts.objects[head].tolist() == [0, 0, 0]  # removed from GT and prediction
    others = [j for j in range(NUM_JOINTS) if j not in head]
    assert counts.misses[others].tolist() == [1] * len(others)


def _video(poses_per_frame, ids_per_frame, with_head=True):
    images = [PoseTrackImage(id=i, file_name=f"images/val/s/{i:06d}.jpg", is_labeled=True)
              for i in range(len(poses_per_frame))]
    people = [[PoseTrackPerson(image_id=i, keypoints=p, track_id=t,
                               bbox_head=tuple(HEAD[0]) if with_head else None)
               for p, t in zip(poses, ids, strict=True)]
              for i, (poses, ids) in enumerate(zip(poses_per_frame, ids_per_frame, strict=True))]
    return PoseTrackVideo(images, people)


def test_last_evaluated_frame_is_dropped_like_poseval():
    gt = _video([[_pose()], [], [_pose()], [_pose()]], [[0], [], [0], [0]])
    pred = _video([[_pose()], [], [_pose()], []], [[1], [], [1], []], with_head=False)
    dropped = evaluate_video(gt, pred)
    kept = evaluate_video(gt, pred, drop_last_frame=False)
    assert dropped.frames == 2 and summarise([dropped])["MOTA"] == 1.0
    # the last frame adds poseval's dummy miss and false positive: 1 - 2 / 3 per joint
    assert kept.frames == 3 and summarise([kept])["MOTA"] == pytest.approx(1 / 3)


def test_motmetrics_cross_check_on_random_sequences():
    mm = pytest.importorskip("motmetrics")
    rng = np.random.default_rng(0)
    for trial in range(20):
        ours = ClearAccumulator()
        theirs = mm.MOTAccumulator(auto_id=True)
        for _ in range(12):
            oids = rng.choice(np.arange(1, 6), size=rng.integers(0, 5), replace=False)
            hids = rng.choice(np.arange(10, 17), size=rng.integers(0, 6), replace=False)
            dist = rng.uniform(0, 1, (len(oids), len(hids)))
            dist[dist > 0.5] = np.nan
            ours.update(oids, hids, dist)
            theirs.update(oids, hids, dist)
        names = ["num_misses", "num_switches", "num_false_positives", "num_objects",
                 "num_detections", "num_predictions", "idtp", "idf1"]
        ref = mm.metrics.create().compute(theirs, metrics=names, return_dataframe=False)
        assert ours.misses == ref["num_misses"], trial
        assert ours.switches == ref["num_switches"], trial
        assert ours.false_positives == ref["num_false_positives"], trial
        assert ours.objects == ref["num_objects"], trial
        assert ours.matches + ours.switches == ref["num_detections"], trial
        assert ours.predictions == ref["num_predictions"], trial
        assert ours.idtp() == ref["idtp"], trial
        np.testing.assert_allclose(ours.idf1(), ref["idf1"])


# ----------------------------------------------------------------------------- episodes
def _play(env, policy):
    observation, info = env.reset(options={"sequence": env.unwrapped.sequence_names[0]})
    total, steps, terminated = 0.0, 0, False
    while not terminated:
        observation, reward, terminated, _, info = env.step(policy(env.unwrapped, observation))
        total += reward
        steps += 1
    return total, steps, info


def _oracle(base, observation):
    people = base.sequence.ground_truth.people[base._k]
    keypoints = np.array([p.keypoints for p in people], np.float32).reshape(-1, 17, 3)
    return pack_pose_tracks([p.track_id + 1 for p in people], keypoints, base.max_tracks)


def _fresh_ids(base, observation):
    keypoints, _ = unpack_poses(observation)
    start = 1 + 1000 * base._k
    return pack_pose_tracks(np.arange(start, start + len(keypoints)), keypoints, base.max_tracks)


def test_synthetic_data_is_posetrack_like():
    env = gym.make("UniTrack/PoseTrack-v0")
    base = env.unwrapped
    assert base.detection_source == "synthetic" and len(base.sequence_names) == 2
    seq = base.dataset.load(base.sequence_names[0])
    labelled = [bool(im.is_labeled) for im in seq.images]
    assert labelled == labeled_frames(seq.length).tolist() and not all(labelled)
    ids_per_frame = [{p.track_id for p in people} for people in seq.ground_truth.people]
    assert any(len(ids) >= 4 for ids in ids_per_frame)
    assert any(im.ignore_regions for im in seq.images)  # the standing person
    occluded = [np.count_nonzero(~p.annotated[[0, 1, 2] + list(range(5, 17))])
                for people in seq.ground_truth.people for p in people]
    assert max(occluded) >= 5  # crossings and the occluder hide joints
    env.close()


def test_oracle_scores_one_and_reward_sums_to_the_numerator(tmp_path):
    env = gym.make("UniTrack/PoseTrack-v0")
    base = env.unwrapped
    total, steps, info = _play(env, _oracle)
    assert steps == base.sequence_length(base.sequence_names[0])
    m = info["metrics"]
    assert m["MOTA"] == m["IDF1"] == m["Precision"] == m["Recall"] == 1.0 and m["IDSW"] == 0
    assert total == m["num_objects"] > 0
    base.write_episode(tmp_path)
    report = base.score_folder(tmp_path, [base.sequence_names[0]])
    assert report.combined["MOTA"] == 1.0
    env.close()


def test_fresh_ids_on_detections_switch_and_rescore_identically(tmp_path):
    env = gym.make("UniTrack/PoseTrack-v0")
    base = env.unwrapped
    total, _, info = _play(env, _fresh_ids)
    m = info["metrics"]
    assert m["IDSW"] > 100 and m["IDF1"] < 0.2 and 0.5 < m["Recall"] < 1.0
    pooled = total / m["num_objects"]
    assert pooled == pytest.approx(1 - (m["num_misses"] + m["num_false_positives"] + m["IDSW"])
                                   / m["num_objects"])
    base.write_episode(tmp_path)
    rescored = base.score_folder(tmp_path, [base.sequence_names[0]]).combined
    for key in ("MOTA", "IDF1", "IDSW", "MOTP", "Precision", "Recall"):
        assert rescored[key] == pytest.approx(m[key])
    env.close()


def test_invalid_actions_are_rejected_before_recording():
    env = gym.make("UniTrack/PoseTrack-v0")
    env.reset(seed=0)
    base = env.unwrapped
    bad = [
        {"ids": np.array([1, 1]), "keypoints": np.zeros((2, 17, 3), np.float32)},
        {"ids": np.array([0]), "keypoints": np.zeros((1, 17, 3), np.float32)},
        {"ids": np.array([1]), "keypoints": np.zeros((1, 15, 3), np.float32)},
        {"ids": np.array([1]), "keypoints": np.full((1, 17, 3), np.nan, np.float32)},
        {"ids": np.array([1]), "keypoints": np.full((1, 17, 3), 2.0, np.float32)},
    ]
    for action in bad:
        with pytest.raises(InvalidActionError):
            env.step(action)
    assert base._results == []
    env.close()


def test_test_split_runs_without_metrics(tmp_path):
    env = gym.make("UniTrack/PoseTrack-v0", split="test")
    base = env.unwrapped
    assert not base.has_ground_truth(base.sequence_names[0])
    total, steps, info = _play(env, _fresh_ids)
    assert total == 0.0 and "metrics" not in info and steps == 40
    base.write_episode(tmp_path)
    assert read_posetrack_json(tmp_path / f"{base.sequence_names[0]}.json").people[5]
    env.close()


def test_real_fixture_episode_with_oracle_detections(shared_data):
    root = shared_data / "PoseTrack2018"
    env = gym.make("UniTrack/PoseTrack-v0", root=root, drop_last_frame=False)
    base = env.unwrapped
    observation, info = env.reset(options={"sequence": "012834_mpii_test"})
    assert info["oracle_detections"] and info["nframes_declared"] == 140
    assert info["image_size"] == (1080, 1920) and base.sequence_length("012834_mpii_test") == 1
    assert observation["num_people"] == 11
    total, steps, info = _play(env, _oracle)
    assert steps == 1 and info["metrics"]["MOTA"] == 1.0
    strict = gym.make("UniTrack/PoseTrack-v0", root=root)  # poseval drops the only frame
    _, _, info = _play(strict, _oracle)
    assert np.isnan(info["metrics"]["MOTA"]) and info["metrics"]["num_frames"] == 0
    test = PoseTrackDataset(root, "test")
    assert test.sequence_names == ["000001_mpiinew_test"] and test.sequence_length(
        "000001_mpiinew_test") == 5
    env.close()
    strict.close()
