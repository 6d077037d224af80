"""UniTrack/DAVIS-v0: episodes, known-answer scores, palette PNG results, errors, layouts."""

from __future__ import annotations

import pickle
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from PIL import Image as PILImage

import unitrack_env
from unitrack_env.datasets.davis import DAVIS_PALETTE, DAVISDataset, read_label_png
from unitrack_env.datasets.synthetic import davis as synthetic_davis
from unitrack_env.datasets.synthetic.scene_model import SceneConfig
from unitrack_env.envs.davis import DAVISEnv
from unitrack_env.errors import DataFormatError, InvalidActionError
from unitrack_env.metrics.vos import evaluate_vos_sequence
from unitrack_env.spaces import LabelMap

ENV_ID = "UniTrack/DAVIS-v0"


def run_episode(env, sequence, policy):
    """Play one episode with ``policy(observation, t)``; return rewards and every info."""
    observation, info = env.reset(options={"sequence": sequence})
    rewards, infos, t = [], [info], 0
    terminated = False
    while not terminated:
        observation, reward, terminated, truncated, info = env.step(policy(observation, t))
        assert not truncated
        assert set(observation) == {"frame", "init_labels", "num_objects"}
        rewards.append(reward)
        infos.append(info)
        t += 1
    return np.array(rewards), infos


def annotations(env, sequence):
    """What an oracle may know, read through the reader (never through observations)."""
    return DAVISDataset(env.dataset.root, env.dataset.split).load(sequence).read_annotations()


def without_void(labels):
    return np.where(labels == 255, 0, labels).astype(np.uint8)


@pytest.fixture
def env():
    environment = gym.make(ENV_ID).unwrapped
    yield environment
    environment.close()


def test_registered_as_vos_and_both_make_forms():
    assert ENV_ID in unitrack_env.env_ids("vos")
    made = gym.make("unitrack_env:UniTrack/DAVIS-v0")
    assert isinstance(made.unwrapped, DAVISEnv) and made.unwrapped.synthetic
    made.close()


def test_synthetic_default_is_in_the_exact_davis_layout(env):
    root = env.dataset.root
    sets = root / "ImageSets" / "2017"
    assert (sets / "val.txt").read_text() == "syn-crossing\nsyn-occluded\n"
    assert (sets / "train.txt").read_text() == "syn-walk\n"
    assert (sets / "test-dev.txt").read_text() == "syn-test\n"
    png = root / "Annotations" / "480p" / "syn-crossing" / "00000.png"
    with PILImage.open(png) as image:
        assert image.mode == "P"
        np.testing.assert_array_equal(
            np.asarray(image.getpalette(), np.uint8).reshape(-1, 3)[:8], DAVIS_PALETTE[:8])
    assert (root / "JPEGImages" / "480p" / "syn-crossing" / "00029.jpg").is_file()
    test_dev = sorted((root / "Annotations" / "480p" / "syn-test").iterdir())
    assert [p.name for p in test_dev] == ["00000.png"]  # first frame only, like test-dev
    crossing = env.dataset.load("syn-crossing")
    labels = crossing.read_annotations()
    assert crossing.object_ids == (1, 2, 3) and crossing.image_size == (432, 240)
    assert (labels == 255).any()  # void borders
    assert env.dataset.load("syn-occluded").object_ids == (1, 2, 3)
    # The crossing pair occlude each other: an object loses most of its pixels for a while.
    pixels = np.array([[(frame == k).sum() for k in (1, 2)] for frame in labels])
    assert (pixels.min(axis=0) < 0.5 * pixels[0]).any()


def test_oracle_scores_one_and_return_is_j_mean(env, tmp_path):
    for name in env.sequence_names:
        gt = annotations(env, name)
        rewards, infos = run_episode(env, name, lambda obs, t, gt=gt: without_void(gt[t]))
        assert len(rewards) == env.sequence_length(name) == len(gt)
        assert rewards[0] == 0.0 and rewards[-1] == 0.0  # given / dropped by DAVIS
        np.testing.assert_allclose(rewards[1:-1], 1.0)
        metrics = infos[-1]["metrics"]
        assert metrics["J-Mean"] == 1.0 and metrics["F-Mean"] == 1.0
        assert metrics["J&F-Mean"] == 1.0
        env.write_episode(tmp_path)
    report = env.score_folder(tmp_path, env.sequence_names)
    assert report.combined["J&F-Mean"] == 1.0 and report.benchmark == "DAVIS-2017"


def test_repeat_first_mask_matches_the_official_procedure(env, tmp_path):
    name = "syn-crossing"
    gt = annotations(env, name)
    first = without_void(gt[0])
    rewards, infos = run_episode(env, name, lambda obs, t: without_void(obs["init_labels"]))
    metrics = infos[-1]["metrics"]
    expected = evaluate_vos_sequence(gt, [first] * len(gt), (1, 2, 3), sequence_name=name)
    assert metrics == pytest.approx(expected.summary, abs=1e-12)
    assert 0.0 < metrics["J-Mean"] < 0.6  # the people walk away from their first masks
    assert rewards.sum() / (len(gt) - 2) == pytest.approx(metrics["J-Mean"])
    assert infos[1]["j"].shape == (3,)  # per-object J, also on the unscored first frame
    env.write_episode(tmp_path)
    written = sorted((tmp_path / name).iterdir())
    assert [p.stem for p in written] == [f"{t:05d}" for t in range(len(gt))]
    with PILImage.open(written[5]) as image:
        assert image.mode == "P"
    np.testing.assert_array_equal(read_label_png(written[5]), first)
    assert env.score_folder(tmp_path, [name]).per_sequence[name] == metrics


def test_observations_and_info(env):
    observation, info = env.reset(options={"sequence": "syn-crossing"})
    assert env.observation_space.contains(observation)
    labels = observation["init_labels"]
    assert labels.dtype == np.uint8 and labels.shape == (240, 432)
    assert set(np.unique(labels)) == {0, 1, 2, 3, 255}  # as shipped, void included
    assert observation["num_objects"] == 3 and info["object_ids"] == (1, 2, 3)
    assert info["frame_index"] == 0 and info["image_size"] == (240, 432)
    assert info["frame_rate"] == 24.0 and info["seq_length"] == 30
    labels[:] = 0  # observations are fresh arrays: changing one changes nothing else
    observation, *_ = env.step(without_void(env.sequence.read_annotation(0)))
    assert (observation["init_labels"] > 0).any()


def test_invalid_actions_raise_before_anything_is_recorded(env):
    observation, _ = env.reset(options={"sequence": "syn-crossing"})
    good = without_void(observation["init_labels"])
    env.step(good)
    for bad, match in [
        (good[:-1], r"frame's size.*\(240, 432\)"),
        (good[None], r"frame's size"),
        (good.astype(np.float32), "integer label map"),
        (good > 0, "integer label map"),
        (np.full_like(good, 255), "255 is DAVIS's void label"),
        (np.full_like(good, 9), r"labels \[9\].*allowed: 0 \(background\) and \[1, 2, 3\]"),
        (np.full(good.shape, -1, np.int64), "must lie in"),
    ]:
        with pytest.raises(InvalidActionError, match=match):
            env.step(bad)
    assert len(env.episode_results()) == 1
    env.step(good.astype(np.int64))  # argmax output need not be cast
    assert len(env.episode_results()) == 2


def test_action_space_samples_valid_maps_for_the_current_episode(env):
    for name in ("syn-crossing", "syn-occluded"):
        env.reset(options={"sequence": name})
        sample = env.action_space.sample()
        assert sample.shape == (240, 432) and env.action_space.contains(sample)
        assert set(np.unique(sample)) <= {0, 1, 2, 3}
        env.step(sample)


def test_test_dev_split_runs_without_reward_or_metrics(tmp_path):
    environment = DAVISEnv(split="test-dev")
    assert not environment.has_ground_truth("syn-test")
    rewards, infos = run_episode(environment, "syn-test",
                                 lambda obs, t: without_void(obs["init_labels"]))
    assert (rewards == 0).all() and "metrics" not in infos[-1]
    assert "j" in infos[1] and "j" not in infos[2]  # only the first frame is annotated
    environment.write_episode(tmp_path)
    assert len(list((tmp_path / "syn-test").iterdir())) == environment.sequence_length("syn-test")


def _write_mixed_sizes(root: Path) -> None:
    small = dict(synthetic_davis._SCENE, width=300, height=200,
                 object_height_range=(60.0, 110.0))
    spec = synthetic_davis.DAVISSpec(sequences=(
        synthetic_davis.SyntheticDAVISSequence(
            "small", "val", SceneConfig(num_frames=24, seed=4, **small), num_objects=2),
        synthetic_davis.SyntheticDAVISSequence(
            "wide", "val", SceneConfig(num_frames=30, seed=1, **synthetic_davis._SCENE),
            num_objects=3),
    ))
    synthetic_davis.write_davis(root, spec=spec)


def test_sequences_of_different_sizes_keep_the_space_contract(tmp_path):
    _write_mixed_sizes(tmp_path)
    environment = gym.make(ENV_ID, root=tmp_path)
    check_env(environment.unwrapped)
    sizes = []
    for name in ("small", "wide", "small"):
        observation, info = environment.reset(options={"sequence": name})
        assert environment.observation_space.contains(observation)
        sizes.append(observation["frame"].shape[:2])
        environment.step(environment.action_space.sample())
    assert sizes == [(200, 300), (240, 432), (200, 300)]
    clone = pickle.loads(pickle.dumps(environment))
    assert clone.reset(options={"sequence": "wide"})[0]["num_objects"] == 3
    environment.close()


def test_render_overlays_the_last_label_map():
    environment = gym.make(ENV_ID, render_mode="rgb_array")
    observation, _ = environment.reset(options={"sequence": "syn-crossing"})
    before = environment.render()
    labels = without_void(observation["init_labels"])
    inside = labels == 1
    assert (before[inside] != observation["frame"][inside]).any()
    environment.step(np.zeros_like(labels))
    np.testing.assert_array_equal(environment.render(), observation["frame"])  # nothing drawn
    environment.close()


def test_score_folder_errors_name_the_file(env, tmp_path):
    name = "syn-occluded"
    run_episode(env, name, lambda obs, t: without_void(obs["init_labels"]))
    env.write_episode(tmp_path)
    target = tmp_path / name / "00003.png"
    target.unlink()
    with pytest.raises(DataFormatError, match="00003.png.*not found"):
        env.score_folder(tmp_path, [name])
    from unitrack_env.datasets.davis import write_label_png

    write_label_png(target, np.full((240, 432), 7, np.uint8))
    with pytest.raises(DataFormatError, match=r"00003.png.*labels \[7\]"):
        env.score_folder(tmp_path, [name])
    write_label_png(target, np.zeros((10, 10), np.uint8))
    with pytest.raises(DataFormatError, match="00003.png.*10x10"):
        env.score_folder(tmp_path, [name])
    (tmp_path / name / "00000.png").unlink()  # the given frame is not read, as officially
    write_label_png(target, np.zeros((240, 432), np.uint8))
    assert env.score_folder(tmp_path, [name]).per_sequence[name]["J-Mean"] < 1


def test_unknown_sequences_and_splits_are_explained(tmp_path):
    with pytest.raises(ValueError, match="available: syn-crossing, syn-occluded"):
        DAVISEnv(sequences=["bear"])
    with pytest.raises(DataFormatError, match="splits found: test-dev, train, val"):
        DAVISEnv(split="test-challenge")
    with pytest.raises(DataFormatError, match="JPEGImages/480p"):
        DAVISEnv(root=tmp_path)


def test_label_map_space():
    space = LabelMap(100, 200, max_label=4, seed=0)
    assert space.contains(np.zeros((100, 200), np.uint8))
    assert not space.contains(np.zeros((101, 200), np.uint8))
    assert not space.contains(np.full((5, 5), 5, np.uint8))
    assert not space.contains(np.zeros((5, 5), np.int64))
    assert not space.contains(np.zeros((5, 5, 1), np.uint8))
    assert space.contains(space.sample())  # before narrow: a small map within bounds
    space.narrow(30, 40, (0, 2))
    sample = space.sample()
    assert sample.shape == (30, 40) and set(np.unique(sample)) == {0, 2}
    assert space == LabelMap(100, 200, max_label=4) != LabelMap(100, 200, max_label=5)
    with pytest.raises(ValueError, match="0..4"):
        space.narrow(30, 40, (0, 5))
    with pytest.raises(ValueError, match="0..255"):
        LabelMap(10, 10, max_label=256)


# --------------------------------------------------------------------------- real data


@pytest.fixture
def real_root(shared_data: Path) -> Path:
    return shared_data / "DAVIS"


def test_real_blackswan_and_dog_repeat_mask_and_oracle(real_root, tmp_path):
    environment = DAVISEnv(root=real_root)
    assert environment.sequence_names == ["blackswan", "dog"]
    for name in environment.sequence_names:
        gt = annotations(environment, name)
        _, infos = run_episode(environment, name, lambda obs, t, gt=gt: gt[t])
        assert infos[-1]["metrics"]["J&F-Mean"] == 1.0
    rewards, infos = run_episode(environment, "blackswan",
                                 lambda obs, t: without_void(obs["init_labels"]))
    assert infos[0]["image_size"] == (480, 854) and len(rewards) == 50
    metrics = infos[-1]["metrics"]
    # DAVIS-2017 semi-supervised J (frames 1..48). The reference 0.547 also counts
    # the last frame: (48 * J-Mean + J(frame 49)) / 49.
    assert metrics["J-Mean"] == pytest.approx(0.5450, abs=5e-4)
    last_j = run_last_j(environment)
    assert (48 * metrics["J-Mean"] + last_j) / 49 == pytest.approx(0.547, abs=5e-4)
    environment.write_episode(tmp_path)
    _, infos = run_episode(environment, "dog", lambda obs, t: without_void(obs["init_labels"]))
    environment.write_episode(tmp_path)
    assert 0.2 < infos[-1]["metrics"]["J-Mean"] < 0.45  # the dog runs off its first mask
    report = environment.score_folder(tmp_path, ["blackswan", "dog"])
    assert report.per_sequence["blackswan"] == metrics
    assert report.combined["J-Mean"] == pytest.approx(
        (metrics["J-Mean"] + infos[-1]["metrics"]["J-Mean"]) / 2)  # one object each
    environment.close()


def run_last_j(environment) -> float:
    """J of the first mask on the last frame of the current sequence."""
    sequence = environment.sequence
    first = without_void(sequence.read_annotation(0))
    last = sequence.read_annotation(sequence.num_frames - 1)
    return float(((first == 1) & (last == 1)).sum() / ((first == 1) | (last == 1)).sum())


def test_real_tennis_multi_object_with_void(real_root, tmp_path):
    environment = DAVISEnv(root=real_root, split="train")
    observation, info = environment.reset()
    assert info["sequence"] == "tennis" and info["object_ids"] == (1, 2)
    assert 255 in observation["init_labels"] and observation["num_objects"] == 2
    with pytest.raises(InvalidActionError, match="void"):
        environment.step(observation["init_labels"])
    _, reward, terminated, _, info = environment.step(without_void(observation["init_labels"]))
    assert reward == 0.0 and not terminated and info["j"].shape == (2,)
    _, reward, terminated, _, info = environment.step(without_void(observation["init_labels"]))
    assert terminated and reward == 0.0
    # Two frames: DAVIS drops the first and the last, nothing is left to score.
    assert all(np.isnan(v) for v in info["metrics"].values())
    environment.write_episode(tmp_path)
    assert sorted(p.name for p in (tmp_path / "tennis").iterdir()) == ["00000.png", "00001.png"]
    environment.close()
