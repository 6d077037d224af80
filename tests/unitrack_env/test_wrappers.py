"""The wrappers: DetectionScoreFilter equals the envs' min_score=, FrameSkip scores every frame."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import unitrack_env
from unitrack_env import spaces as ut_spaces
from unitrack_env.errors import InvalidActionError
from unitrack_env.wrappers import DetectionScoreFilter, FrameSkip

ASSOCIATION_IDS = ["UniTrack/MOT17-v0", "UniTrack/MOTS-v0", "UniTrack/VIS-v0",
                   "UniTrack/PoseTrack-v0"]


def _echo(env, observation):
    """A valid answer for any env: the detections as new tracks, or the given target."""
    base = env.unwrapped
    if base.task == "mot":
        boxes, _ = ut_spaces.unpack_detections(observation)
        return ut_spaces.pack_tracks(np.arange(1, len(boxes) + 1), boxes, base.max_tracks)
    if base.task in ("mots", "vis"):
        n = observation["num_detections"]
        return ut_spaces.pack_mask_ids(np.arange(1, n + 1), base.max_detections)
    if base.task == "posetrack":
        keypoints, _ = ut_spaces.unpack_poses(observation)
        return ut_spaces.pack_pose_tracks(np.arange(1, len(keypoints) + 1), keypoints,
                                          base.max_tracks)
    if base.task == "vos":
        labels = observation["init_labels"].copy()
        labels[labels == 255] = 0
        return labels
    return observation["init_box" if base.task == "sot" else "init_keypoints"]


def _play(env, sequence):
    observation, _ = env.reset(options={"sequence": sequence})
    observations, rewards, done, info = [observation], [], False, {}
    while not done:
        observation, reward, terminated, truncated, info = env.step(_echo(env, observation))
        observations.append(observation)
        rewards.append(reward)
        done = terminated or truncated
    return observations, rewards, info


@pytest.mark.parametrize("env_id", ASSOCIATION_IDS)
def test_score_filter_equals_the_min_score_argument(env_id):
    flagged = gym.make(env_id, min_score=0.5)
    wrapped = DetectionScoreFilter(gym.make(env_id), 0.5)
    name = flagged.unwrapped.sequence_names[0]
    seen_a, rewards_a, info_a = _play(flagged, name)
    seen_b, rewards_b, info_b = _play(wrapped, name)
    assert rewards_a == rewards_b
    for a, b in zip(seen_a, seen_b, strict=True):
        assert a.keys() == b.keys()
        for key in a:
            np.testing.assert_array_equal(np.asarray(a[key]), np.asarray(b[key]))
        assert wrapped.observation_space.contains(b)
    assert info_a["metrics"].keys() == info_b["metrics"].keys()
    np.testing.assert_array_equal(list(info_a["metrics"].values()),
                                  list(info_b["metrics"].values()))
    assert flagged.unwrapped.episode_digest() == wrapped.unwrapped.episode_digest()


def test_score_filter_drops_low_scores_and_maps_ids_back():
    env = DetectionScoreFilter(gym.make("UniTrack/MOTS-v0"), 0.0)
    raw, _ = env.env.reset(seed=0)
    scores = np.sort(raw["scores"][:raw["num_detections"]])
    env.min_score = float(scores[len(scores) // 2])  # keeps the upper half
    observation, _ = env.reset(seed=0)
    n = observation["num_detections"]
    assert 0 < n < raw["num_detections"] and len(observation["masks"]) == n
    assert (observation["scores"][:n] >= env.min_score).all()
    observation, *_ = env.step({"ids": np.arange(1, n + 1)})  # one id per kept detection
    _, ids, _ = env.unwrapped._results[0]
    assert sorted(ids.tolist()) == list(range(1, n + 1))
    with pytest.raises(InvalidActionError, match="entries; this frame has"):
        env.step({"ids": np.arange(1, observation["num_detections"] + 2)})


def test_score_filter_needs_detections():
    env = DetectionScoreFilter(gym.make("UniTrack/OTB-v0"), 0.5)
    with pytest.raises(TypeError, match="association environments"):
        env.reset(seed=0)


@pytest.mark.parametrize("env_id", unitrack_env.env_ids())
def test_frame_skip_plays_and_scores_every_frame(env_id, tmp_path):
    env = FrameSkip(gym.make(env_id), 3)
    base = env.unwrapped
    name = base.sequence_names[0]
    length = base.sequence_length(name)
    _, rewards, info = _play(env, name)
    assert len(rewards) == math.ceil(length / 3)
    assert info["frames_played"] == length - 3 * (len(rewards) - 1)
    assert "metrics" in info
    base.write_episode(tmp_path)
    report = base.score_folder(tmp_path, [name])
    np.testing.assert_allclose(list(report.per_sequence[name].values()),
                               list(info["metrics"].values()), equal_nan=True)


def test_frame_skip_holds_the_answer_and_sums_rewards():
    plain, skipping = gym.make("UniTrack/OTB-v0"), FrameSkip(gym.make("UniTrack/OTB-v0"), 2)
    name = plain.unwrapped.sequence_names[0]
    observation, _ = skipping.reset(options={"sequence": name})
    plain.reset(options={"sequence": name})
    box = observation["init_box"] + np.float32(2.0)
    _, reward, *_ = skipping.step(box)
    expected = plain.step(box)[1] + plain.step(box)[1]
    assert reward == pytest.approx(expected)
    recorded = skipping.unwrapped.episode_results()
    np.testing.assert_array_equal(recorded[0], recorded[1])


def test_frame_skip_of_one_is_the_plain_env():
    plain, skipping = gym.make("UniTrack/JHMDB-v0"), FrameSkip(gym.make("UniTrack/JHMDB-v0"), 1)
    name = plain.unwrapped.sequence_names[0]
    _, rewards_a, info_a = _play(plain, name)
    _, rewards_b, info_b = _play(skipping, name)
    assert rewards_a == rewards_b and info_a["metrics"] == info_b["metrics"]


def test_frame_skip_reports_nothing_for_detection_ids():
    env = FrameSkip(gym.make("UniTrack/VIS-v0"), 2)
    observation, _ = env.reset(seed=0)
    env.step(_echo(env, observation))
    assert set(env.unwrapped._tracks) and all(
        set(frames) == {0} for frames in env.unwrapped._tracks.values())


@pytest.mark.parametrize("skip", [0, -1, 1.5])
def test_frame_skip_refuses_a_bad_skip(skip):
    with pytest.raises(ValueError, match="skip must be"):
        FrameSkip(gym.make("UniTrack/OTB-v0"), skip)
