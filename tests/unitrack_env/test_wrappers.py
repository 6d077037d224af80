"""The association envs' min_score= filters detections; FrameSkip scores every frame."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import unitrack_env
from unitrack_env import spaces as ut_spaces
from unitrack_env.wrappers import FrameSkip

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
    if base.task == "points":  # every active query: occluded (a valid answer on any frame)
        size = observation["active"].shape[0]
        return {"tracks": np.zeros((size, 2), np.float32), "occluded": np.ones(size, np.int8)}
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
def test_min_score_is_the_one_score_filter(env_id):
    # Every association env filters by score with min_score= (the agent and no wrapper do).
    plain, flagged = gym.make(env_id), gym.make(env_id, min_score=0.5)
    name = plain.unwrapped.sequence_names[0]
    seen_all, _, _ = _play(plain, name)
    seen_kept, _, info = _play(flagged, name)
    count = "num_people" if "num_people" in seen_all[0] else "num_detections"
    dropped = 0
    for a, b in zip(seen_all, seen_kept, strict=True):
        scores = np.asarray(a["scores"][: a[count]])
        assert b[count] == int((scores >= 0.5).sum())
        assert (np.asarray(b["scores"][: b[count]]) >= 0.5).all()
        assert flagged.observation_space.contains(b)
        dropped += a[count] - b[count]
    assert dropped > 0 and "metrics" in info


@pytest.mark.parametrize("env_id", unitrack_env.env_ids())
def test_frame_skip_plays_and_scores_every_frame(env_id, tmp_path):
    env = FrameSkip(gym.make(env_id), 3)
    base = env.unwrapped
    name = base.sequence_names[0]
    length = base.sequence_length(name)
    _, rewards, info = _play(env, name)
    # points: a frame that reveals queries ends a step early (the test below counts frames)
    if base.task != "points":
        assert len(rewards) == math.ceil(length / 3)
        assert info["frames_played"] == length - 3 * (len(rewards) - 1)
    assert "metrics" in info
    base.write_episode(tmp_path)
    report = base.score_folder(tmp_path, [name])
    # The episode scores the float32 boxes it observed, the file holds them to 1e-3 (a few
    # 1e-6 pixels apart): mean IoUs (LocA, MOTP) may differ in the 7th digit (SportsMOT's
    # synthetic default: 1.7e-7 relative).
    np.testing.assert_allclose(list(report.per_sequence[name].values()),
                               list(info["metrics"].values()), rtol=1e-6, equal_nan=True)


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


def _play_points(env, sequence):
    """Play a TAP-Vid env with :func:`_echo`; ``{(query, reverse): frame it was shown on}``."""
    shown = {}

    def note(observation, info):
        for query in observation["query_ids"][: observation["num_new"]]:
            shown.setdefault((int(query), int(observation["reverse"])), info["frame_index"])

    observation, info = env.reset(options={"sequence": sequence})
    note(observation, info)
    done, played = False, []
    while not done:
        observation, _, terminated, truncated, info = env.step(_echo(env, observation))
        note(observation, info)
        played.append(info["frames_played"])
        done = terminated or truncated
    return shown, played, info


@pytest.mark.parametrize("env_id", ["UniTrack/TAPVid-DAVIS-v0", "UniTrack/TAPVid-Kinetics-v0"])
@pytest.mark.parametrize("mode", ["first", "strided"])
def test_frame_skip_shows_every_point_query_on_its_own_frame(env_id, mode):
    # A query (t, y, x) is defined on frame t: the agent must be shown it there (in the
    # reversed pass of "strided" too), never have its rows filled in by the wrapper unseen.
    env = FrameSkip(gym.make(env_id, query_mode=mode), 3)
    base = env.unwrapped
    for name in base.sequence_names:
        frames = base.scoring.queries(name).query_frames
        shown, played, info = _play_points(env, name)
        expected = {(q, 0): int(t) for q, t in enumerate(frames)}
        if mode == "strided":
            expected |= {(q, 1): int(t) for q, t in enumerate(frames) if t > 0}
        assert shown == expected
        assert sum(played) == base.sequence_length(name) and max(played) == 3
        assert "metrics" in info
