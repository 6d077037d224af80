"""UniTrack/OTB-v0: episodes, known-answer scores, result files, errors, synthetic layout."""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import unitrack_env
from unitrack_env.benchmarks.otb import format_otb_results
from unitrack_env.datasets.otb import OTBDataset
from unitrack_env.datasets.sot import read_box_file
from unitrack_env.envs.otb import ACTION_COLOUR, OTBEnv
from unitrack_env.errors import DataFormatError, InvalidActionError, UnknownSequenceError
from unitrack_env.metrics.sot import evaluate_sot_sequence, overlap_per_frame

ENV_ID = "UniTrack/OTB-v0"
#: A perfect tracker's AUC under the OTB toolkit: no overlap is > 1, so 20 of 21 thresholds.
PERFECT_AUC = 20 / 21


def run_episode(env, sequence, policy):
    """Play one episode with ``policy(observation, t)``; return rewards and every info."""
    observation, info = env.reset(options={"sequence": sequence})
    rewards, infos, t = [], [info], 0
    terminated = False
    while not terminated:
        observation, reward, terminated, truncated, info = env.step(policy(observation, t))
        assert not truncated
        assert set(observation) == {"frame", "init_box"}
        rewards.append(reward)
        infos.append(info)
        t += 1
    return np.array(rewards), infos


def ground_truth(env, sequence):
    """The boxes an oracle may know, read through the reader (never through observations)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return OTBDataset(env.dataset.root).load(sequence).boxes


@pytest.fixture
def env():
    environment = gym.make(ENV_ID).unwrapped
    yield environment
    environment.close()


def test_registered_as_sot_and_both_make_forms():
    assert ENV_ID in unitrack_env.env_ids("sot")
    assert unitrack_env.task_of(ENV_ID) == "sot"
    made = gym.make("unitrack_env:UniTrack/OTB-v0")
    assert isinstance(made.unwrapped, OTBEnv) and made.unwrapped.synthetic
    made.close()


def test_synthetic_default_is_in_the_exact_otb_layout(env):
    root = env.dataset.root
    assert env.sequence_names == ["SynCrossing", "SynLateStart", "SynWalker"]
    crossing = (root / "SynCrossing" / "groundtruth_rect.txt").read_text()
    assert "\t" in crossing and "," not in crossing  # tab-separated like OTB's Crossing
    late = root / "SynLateStart"
    assert sorted(p.name for p in (late / "img").iterdir())[0] == "0011.jpg"
    assert not (late / "groundtruth_rect.txt").read_text().endswith("\n")  # like Human3
    walker = (root / "SynWalker" / "groundtruth_rect.txt").read_text().splitlines()
    assert len(walker) == 40 and all(len(line.split(",")) == 4 for line in walker)
    for name in env.sequence_names:
        boxes = env.dataset.load(name).boxes
        assert (boxes > 0).all() and (boxes == np.round(boxes)).all()  # valid 1-based ints
        assert np.ptp(boxes[:, 0]) > 20  # the target moves
        assert env.sequence_length(name) == len(boxes)


def test_oracle_gets_the_toolkit_maximum_and_files_round_trip(env, tmp_path):
    for name in env.sequence_names:
        gt = ground_truth(env, name)
        rewards, infos = run_episode(env, name, lambda obs, t, gt=gt: gt[t])
        assert len(rewards) == env.sequence_length(name) == len(gt)
        np.testing.assert_allclose(rewards, 1.0)
        metrics = infos[-1]["metrics"]
        assert metrics["AUC"] == pytest.approx(PERFECT_AUC)
        assert metrics["Precision@20px"] == 1.0 and metrics["AverageOverlap"] == 1.0
        env.write_episode(tmp_path)
        np.testing.assert_array_equal(read_box_file(tmp_path / f"{name}.txt"), gt)
    report = env.score_folder(tmp_path, env.sequence_names)
    assert report.combined["AUC"] == pytest.approx(PERFECT_AUC)
    assert set(report.per_sequence) == set(env.sequence_names)


def test_repeat_first_box_scores_as_the_toolkit_and_return_is_the_mean_overlap(env, tmp_path):
    name = "SynWalker"
    gt = ground_truth(env, name)
    observation, info = env.reset(options={"sequence": name})
    init = observation["init_box"]
    assert init.dtype == np.float32 and init.tolist() == gt[0].tolist()
    rewards, infos = run_episode(env, name, lambda obs, t: obs["init_box"])
    assert rewards[0] == 1.0  # the toolkit scores the given box on frame 1
    expected = evaluate_sot_sequence(np.tile(gt[0], (len(gt), 1)), gt).as_dict()
    assert infos[-1]["metrics"] == expected
    assert 0.0 < expected["AUC"] < 0.5  # a box that never moves loses the walker
    np.testing.assert_allclose(rewards[1:], overlap_per_frame(np.tile(gt[0], (len(gt) - 1, 1)),
                                                              gt[1:]))
    assert rewards.sum() / len(rewards) == pytest.approx(expected["AverageOverlap"])
    env.write_episode(tmp_path)
    assert env.score_folder(tmp_path, [name]).per_sequence[name] == expected


def test_step_semantics_frame_numbers_and_info(env):
    observation, info = env.reset(options={"sequence": "SynLateStart"})
    assert info["frame_index"] == 11  # the benchmark's own number of the first frame
    assert info["seq_length"] == 30 and info["image_size"] == (240, 320)
    assert info["has_ground_truth"] and info["synthetic"]
    frame = observation["frame"]
    assert frame.dtype == np.uint8 and frame.shape == (240, 320, 3)
    assert (frame[..., 0] == frame[..., 1]).all()  # grayscale JPEG given as RGB
    observation, reward, terminated, _, info = env.step(observation["init_box"])
    assert info["frame_index"] == 12 and not terminated and info["iou"] == reward
    assert observation["init_box"].tolist() == env.sequence.boxes[0].tolist()


def test_invalid_actions_raise_before_anything_is_recorded(env):
    observation, _ = env.reset(options={"sequence": "SynWalker"})
    good = observation["init_box"]
    env.step(good)
    for bad, match in [
        (np.array([1, 2, np.nan, 4], np.float32), "non-finite"),
        (np.array([1, 2, -3, 4], np.float32), "negative"),
        (np.zeros(3, np.float32), r"shape \(4,\)"),
        (np.zeros((1, 4), np.float32), r"shape \(4,\)"),
        ("box", r"shape \(4,\)"),
        (np.array([True, True, True, True]), "numbers"),
        (np.array([1, 2, 3e6, 4]), "bound"),
    ]:
        with pytest.raises(InvalidActionError, match=match):
            env.step(bad)
    assert len(env.episode_results()) == 1
    env.step([float(v) for v in good])  # plain lists of numbers are fine
    assert len(env.episode_results()) == 2


def test_zero_size_box_is_repaired_like_the_toolkit(env, tmp_path):
    name = "SynCrossing"
    gt = ground_truth(env, name)

    def policy(obs, t):
        return np.array([10, 10, 0, 0], np.float32) if t == 2 else gt[t]

    rewards, infos = run_episode(env, name, policy)
    assert rewards[2] == pytest.approx(overlap_per_frame(gt[1], gt[2])[0])  # previous box
    env.write_episode(tmp_path)
    assert (tmp_path / f"{name}.txt").read_text().splitlines()[2] == "10,10,0,0"
    raw = read_box_file(tmp_path / f"{name}.txt")
    assert infos[-1]["metrics"] == evaluate_sot_sequence(raw, gt).as_dict()


def test_result_file_format_is_short_and_exact():
    text = format_otb_results(np.array([[205, 151, 17, 50], [1.5, 2.25, 3.1, 4]]))
    assert text == "205,151,17,50\n1.5,2.25,3.1,4\n"


def test_render_draws_the_last_box(tmp_path):
    env = gym.make(ENV_ID, render_mode="rgb_array")
    observation, _ = env.reset(options={"sequence": "SynWalker"})
    before = env.render()
    assert before.shape == observation["frame"].shape and before.dtype == np.uint8
    box = np.array([21, 31, 40, 60], np.float32)  # 1-based: left edge at column 20
    env.step(box)
    image = env.render()
    green = np.asarray(ACTION_COLOUR)
    assert np.abs(image[60, 20].astype(int) - green).max() < 20  # on the box's left edge
    assert np.abs(image[60, 30].astype(int) - green).max() > 100  # inside: the frame
    np.testing.assert_array_equal(image[60, 30], observation["frame"][60, 30])
    env.close()


def test_errors_name_what_to_fix(env, tmp_path):
    with pytest.raises(UnknownSequenceError, match="SynWalker"):
        env.reset(options={"sequence": "Basketball"})
    with pytest.raises(RuntimeError, match="reset"):
        OTBEnv().step(np.zeros(4))
    (tmp_path / "SynWalker.txt").write_text("1,2,3,4\n")
    with pytest.raises(DataFormatError, match="1 boxes but 'SynWalker' has 40 frames"):
        env.score_folder(tmp_path, ["SynWalker"])
    with pytest.raises(DataFormatError, match="no result file"):
        env.score_folder(tmp_path, ["SynCrossing"])
    with pytest.raises(DataFormatError, match="no sequence folders"):
        OTBEnv(root=tmp_path)


def test_invalid_first_box_is_a_data_error(env, tmp_path):
    shutil.copytree(env.dataset.root / "SynWalker", tmp_path / "SynWalker")
    gt = tmp_path / "SynWalker" / "groundtruth_rect.txt"
    lines = gt.read_text().splitlines()
    gt.write_text("\n".join(["0,0,0,0", *lines[1:]]) + "\n")
    broken = OTBEnv(root=tmp_path)
    with pytest.raises(DataFormatError, match=r"groundtruth_rect.txt, line 1.*first box"):
        broken.reset()


def test_unitrack_data_variable_is_used(monkeypatch, env, tmp_path):
    shutil.copytree(env.dataset.root / "SynWalker", tmp_path / "OTB" / "SynWalker")
    monkeypatch.setenv("UNITRACK_DATA", str(tmp_path))
    made = OTBEnv()
    assert not made.synthetic and made.sequence_names == ["SynWalker"]


# --------------------------------------------------------------------------- real data


@pytest.fixture
def real_env(shared_data: Path):
    environment = OTBEnv(root=shared_data / "OTB")
    yield environment
    environment.close()


def test_real_crossing_tab_separated_oracle_and_repeat(real_env, tmp_path):
    gt = ground_truth(real_env, "Crossing")
    rewards, infos = run_episode(real_env, "Crossing", lambda obs, t: gt[t])
    assert len(rewards) == 120 and infos[0]["image_size"] == (240, 360)
    assert infos[-1]["metrics"]["AUC"] == pytest.approx(PERFECT_AUC)
    rewards, infos = run_episode(real_env, "Crossing", lambda obs, t: obs["init_box"])
    metrics = infos[-1]["metrics"]
    assert metrics["AUC"] < 0.1 and metrics["Precision@20px"] < 0.2  # the walker leaves
    real_env.write_episode(tmp_path)
    assert real_env.score_folder(tmp_path, ["Crossing"]).per_sequence["Crossing"] == metrics


def test_real_human3_trimmed_copy_runs_over_its_annotated_frames(shared_data):
    with pytest.warns(UserWarning, match="199 of the 1698"):
        environment = OTBEnv(root=shared_data / "OTB", sequences=["Human3"])
        assert environment.sequence_length("Human3") == 199
    observation, info = environment.reset()
    assert info["seq_length"] == 199 and observation["frame"].shape == (640, 480, 3)
    gt = ground_truth(environment, "Human3")
    rewards, infos = run_episode(environment, "Human3", lambda obs, t: gt[t])
    assert len(rewards) == 199 and infos[-1]["metrics"]["Precision@20px"] == 1.0
    environment.close()


def test_toolkit_frame_ranges_tiger1_starts_at_frame_6(tmp_path):
    """Tiger1's first 5 frames are omitted by the toolkit: the episode starts at frame 6."""
    import cv2

    images = tmp_path / "Tiger1" / "img"
    images.mkdir(parents=True)
    for n in range(1, 355):
        cv2.imwrite(str(images / f"{n:04d}.jpg"), np.zeros((6, 8, 3), np.uint8))
    rows = np.array([[n, 2 * n, 10, 20] for n in range(1, 355)], dtype=float)
    (tmp_path / "Tiger1" / "groundtruth_rect.txt").write_text(
        "\n".join(",".join(f"{v:.0f}" for v in row) for row in rows) + "\n")
    environment = OTBEnv(root=tmp_path, decode_frames=False)
    assert environment.sequence_length("Tiger1") == 349
    observation, info = environment.reset()
    assert info["frame_index"] == 6 and observation["init_box"].tolist() == [6, 12, 10, 20]
    rewards, infos = run_episode(environment, "Tiger1", lambda obs, t: rows[5 + t])
    assert len(rewards) == 349 and infos[-1]["frame_index"] == 354
    assert infos[-1]["metrics"]["AUC"] == pytest.approx(PERFECT_AUC)
    environment.write_episode(tmp_path / "out")
    assert len((tmp_path / "out" / "Tiger1.txt").read_text().splitlines()) == 349
