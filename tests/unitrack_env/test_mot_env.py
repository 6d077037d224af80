from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import unitrack_env
from unitrack_env.errors import InvalidActionError, UnknownSequenceError
from unitrack_env.spaces import Image, pack_tracks, unpack_detections

MOT_IDS = unitrack_env.env_ids("mot")


def detections_as_tracks(observation, next_id: int = 1):
    boxes, _ = unpack_detections(observation)
    return pack_tracks(np.arange(next_id, next_id + len(boxes)), boxes, 512)


def play(env, policy=detections_as_tracks, **reset_kwargs):
    observation, info = env.reset(**reset_kwargs)
    rewards, infos = [], [info]
    terminated = False
    while not terminated:
        observation, reward, terminated, truncated, info = env.step(policy(observation))
        assert not truncated
        rewards.append(reward)
        infos.append(info)
    return rewards, infos


@pytest.mark.parametrize("env_id", MOT_IDS)
def test_check_env_passes(env_id):
    env = gym.make(env_id).unwrapped
    check_env(env, skip_render_check=False)
    env.close()


def test_both_make_forms_and_registration_table():
    assert set(MOT_IDS) == {f"UniTrack/{n}-v0" for n in
                            ("MOT15", "MOT16", "MOT17", "MOT20", "DanceTrack", "SportsMOT",
                             "MOTChallenge", "KITTI", "BDD100K")}
    env = gym.make("unitrack_env:UniTrack/MOT16-v0")
    assert env.unwrapped.synthetic and env.unwrapped.benchmark == "MOT16"
    env.close()


@pytest.mark.parametrize("env_id", MOT_IDS)
def test_same_seed_same_episode_and_pickling(env_id):
    env = gym.make(env_id, shuffle=True)
    obs1, info1 = env.reset(seed=7)
    obs2, info2 = env.reset(seed=7)
    assert info1["sequence"] == info2["sequence"]
    for key in obs1:
        np.testing.assert_array_equal(obs1[key], obs2[key])
    clone = pickle.loads(pickle.dumps(env))
    obs3, info3 = clone.reset(seed=7)
    assert info3["sequence"] == info1["sequence"]
    np.testing.assert_array_equal(obs3["frame"], obs1["frame"])
    env.close()
    clone.close()


def test_walks_sequences_in_order_and_reset_option():
    env = gym.make("UniTrack/MOT17-v0")
    names = env.unwrapped.sequence_names
    seen = [env.reset()[1]["sequence"] for _ in range(len(names) + 1)]
    assert seen == names + names[:1]
    assert env.reset(options={"sequence": names[-1]})[1]["sequence"] == names[-1]
    with pytest.raises(UnknownSequenceError, match="this environment has"):
        env.reset(options={"sequence": "nope"})
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(options={"seq": names[0]})


def test_observation_contract_and_no_ground_truth_leak():
    env = gym.make("UniTrack/MOT17-v0")
    observation, info = env.reset(seed=0)
    assert set(observation) == {"frame", "boxes", "scores", "num_detections"}
    assert env.observation_space.contains(observation)
    assert observation["frame"].shape == (*info["image_size"], 3)
    sequence = env.unwrapped.sequence
    n = observation["num_detections"]
    rows = sequence.detections.rows(1)
    np.testing.assert_allclose(observation["boxes"][:n], sequence.detections.boxes[rows], 1e-4)
    assert not np.any(observation["boxes"][n:])
    gt_boxes = sequence.ground_truth.boxes[sequence.ground_truth.rows(1)]
    # Detections are noisy: no observed box equals a ground-truth box exactly.
    assert not any(np.allclose(b, g) for b in observation["boxes"][:n] for g in gt_boxes)
    # Fresh arrays every step (gymnasium contract).
    nxt, *_ = env.step(detections_as_tracks(observation))
    assert not np.shares_memory(nxt["boxes"], observation["boxes"])


def test_episode_return_over_gt_equals_trackeval_mota():
    env = gym.make("UniTrack/MOT17-v0")
    rewards, infos = play(env, seed=0)
    metrics = infos[-1]["metrics"]
    totals = {k: sum(i["clear"][k] for i in infos[1:]) for k in ("tp", "fp", "fn", "idsw")}
    assert totals["tp"] == metrics["CLR_TP"] and totals["fp"] == metrics["CLR_FP"]
    assert totals["fn"] == metrics["CLR_FN"] and totals["idsw"] == metrics["IDSW"]
    assert sum(rewards) / (totals["tp"] + totals["fn"]) == pytest.approx(metrics["MOTA"], 1e-12)
    assert infos[-1]["frame_index"] == infos[0]["seq_length"] == len(rewards)


def test_test_split_runs_without_ground_truth():
    env = gym.make("UniTrack/MOT17-v0", split="test")
    rewards, infos = play(env)
    assert not infos[0]["has_ground_truth"]
    assert set(rewards) == {0.0} and "metrics" not in infos[-1]
    assert len(env.unwrapped.episode_results()) > 0


@pytest.mark.parametrize(
    ("action", "message"),
    [
        ({"ids": np.array([1, 1]), "boxes": np.ones((2, 4))}, "duplicate track ids"),
        ({"ids": np.array([1]), "boxes": np.array([[1, 2, np.nan, 4]])}, "non-finite"),
        ({"ids": np.array([1]), "boxes": np.array([[1, 2, -3, 4]])}, "negative size"),
        ({"ids": np.array([0]), "boxes": np.ones((1, 4))}, "ids must be >= 1"),
        ({"ids": np.array([1, 2]), "boxes": np.ones((1, 4))}, "2 ids but 1 boxes"),
        ({"ids": np.array([1]), "boxes": np.ones((1, 3))}, r"shape \(k, 4\)"),
        ({"ids": np.array(["a"]), "boxes": np.ones((1, 4))}, "must be integers"),
        ({"boxes": np.ones((1, 4))}, "must be a dict with 'ids'"),
        ({"ids": np.ones(3, int), "boxes": np.ones((3, 4)), "num_tracks": 5}, "num_tracks=5"),
    ],
)
def test_invalid_actions_raise_before_recording(action, message):
    env = gym.make("UniTrack/MOT16-v0").unwrapped
    env.reset(seed=0)
    with pytest.raises(InvalidActionError, match=message):
        env.step(action)
    assert len(env.episode_results()) == 0 and env._t == 1


def test_an_invalid_action_names_its_frame():
    env = gym.make("UniTrack/MOT16-v0")
    env.reset(seed=0)
    _, _, _, _, info = env.step({"ids": np.zeros(0, int), "boxes": np.zeros((0, 4))})
    bad = {"ids": np.array([7]), "boxes": np.array([[1.0, 2.0, np.nan, 4.0]])}
    with pytest.raises(InvalidActionError,
                       match=rf"^frame {info['frame_index']}: track 7 has a non-finite box"):
        env.step(bad)


def test_unpadded_action_and_results_format():
    env = gym.make("UniTrack/MOT16-v0").unwrapped
    env.reset(seed=0)
    env.step({"ids": np.array([4, 9]), "boxes": np.array([[1, 2, 3, 4], [5, 6, 7, 8.5]])})
    rows = env.episode_results()
    np.testing.assert_array_equal(rows, [[1, 4, 1, 2, 3, 4, 1, -1, -1, -1],
                                         [1, 9, 5, 6, 7, 8.5, 1, -1, -1, -1]])


def test_render_draws_id_coloured_tracks():
    env = gym.make("UniTrack/MOT16-v0", render_mode="rgb_array")
    observation, _ = env.reset(seed=0)
    before = env.render()
    assert before.shape == observation["frame"].shape and before.dtype == np.uint8
    boxes, _ = unpack_detections(observation)
    env.step(pack_tracks([5], boxes[:1], 512))
    image = env.render()
    assert image.shape == observation["frame"].shape
    assert not np.array_equal(image, observation["frame"])  # something was drawn
    from unitrack_env.envs.motchallenge import MOTChallengeEnv

    with pytest.raises(ValueError, match="render_mode"):
        MOTChallengeEnv("MOT16", render_mode="human")


def test_image_space_bounds():
    space = Image(100, 200)
    assert space.contains(np.zeros((100, 200, 3), np.uint8))
    assert not space.contains(np.zeros((101, 200, 3), np.uint8))
    assert not space.contains(np.zeros((10, 20, 3), np.float32))
    assert space.contains(space.sample())
    assert pickle.loads(pickle.dumps(space)) == space


def test_capacity_errors_are_explained():
    env = gym.make("UniTrack/MOT16-v0", max_detections=1)
    with pytest.raises(ValueError, match="max_detections=1"):
        env.reset(seed=0)
    env = gym.make("UniTrack/MOT16-v0", max_frame_size=(100, 100))
    with pytest.raises(ValueError, match="max_frame_size"):
        env.reset(seed=0)


def test_decode_frames_off_gives_placeholder_frame():
    env = gym.make("UniTrack/MOT16-v0", decode_frames=False)
    observation, _ = env.reset(seed=0)
    assert observation["frame"].shape == (1, 1, 3)


def test_unitrack_data_variable(monkeypatch, tmp_path):
    monkeypatch.setenv("UNITRACK_DATA", str(tmp_path))
    with pytest.raises(ValueError, match="has no 'MOT17' folder"):
        gym.make("UniTrack/MOT17-v0")


def test_real_mot17_episode(mot17_root):
    env = gym.make("unitrack_env:UniTrack/MOT17-v0", root=mot17_root)
    for name in env.unwrapped.sequence_names:
        rewards, infos = play(env, options={"sequence": name})
        metrics = infos[-1]["metrics"]
        assert {"HOTA", "MOTA", "IDF1", "IDSW"} <= set(metrics)
        assert len(rewards) == infos[0]["seq_length"]
        assert infos[0]["image_size"] in {(1080, 1920), (480, 640)}


def test_check_env_on_real_data(mot17_root, mot15_root):
    check_env(gym.make("UniTrack/MOT17-v0", root=mot17_root).unwrapped)
    check_env(gym.make("UniTrack/MOT15-v0", root=mot15_root).unwrapped)


def test_padded_actions_are_in_the_action_space():
    env = gym.make("UniTrack/MOT16-v0")
    action = pack_tracks([3, 9], [[1, 2, 3, 4], [-5, 6, 7, 8]], env.unwrapped.max_tracks)
    assert env.action_space.contains(action)
