"""JHMDB pose propagation: synthetic layout, poses, episodes, results and the repeat-pose floor."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from scipy.io import loadmat

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.agents.base import make_agent
from unitrack_env.datasets.jhmdb import JHMDBDataset, read_joint_positions
from unitrack_env.datasets.synthetic import render_scene
from unitrack_env.datasets.synthetic.jhmdb import DEFAULT_SPEC, PUPPET_ID, puppet_joints
from unitrack_env.datasets.synthetic.poses import (
    SKELETON_JOINTS,
    joint_visibility,
    skeleton_pixels,
)
from unitrack_env.errors import InvalidActionError
from unitrack_env.metrics.pose import pck_counts

CATCH = "catch/Goal_Keeping_Tips_catch_f_cm_np1_fr_med_2"


def _play(env, agent, sequence):
    observation, info = env.reset(options={"sequence": sequence})
    agent.reset(observation, info)
    rewards, terminated = [], False
    while not terminated:
        observation, reward, terminated, _, info = env.step(agent.act(observation))
        rewards.append(reward)
    return rewards, info


class _Oracle:
    """Answers with the ground truth (reads the env's sequence: test-only)."""

    def __init__(self, env):
        self.base = env.unwrapped

    def reset(self, observation, info):
        pass

    def act(self, observation):
        return self.base.sequence.keypoints[self.base._t].astype(np.float32)


def test_skeleton_stays_on_the_silhouette_and_walks():
    video = render_scene(DEFAULT_SPEC.videos[0].scene)
    person = video.object(PUPPET_ID)
    frame = video.frame(0)
    joints = skeleton_pixels(person, 0)
    inside, visible = joint_visibility(joints, frame.instance_map, PUPPET_ID)
    cols, rows = np.round(joints).astype(int).T
    on_body = frame.instance_map[rows[inside], cols[inside]] == PUPPET_ID
    assert on_body.mean() > 0.8  # joints lie on the person's own pixels
    ankle = SKELETON_JOINTS.index("left_ankle")
    x0 = [person.box_at(t)[0] for t in range(20)]
    rel = [skeleton_pixels(person, t)[ankle, 0] - x for t, x in enumerate(x0)]
    assert np.ptp(rel) > 3.0  # the leg swings relative to the body
    visible_counts = []
    for spec in DEFAULT_SPEC.videos:  # the crossing person hides joints in some clips
        clip = render_scene(spec.scene)
        puppet = clip.object(PUPPET_ID)
        visible_counts += [joint_visibility(skeleton_pixels(puppet, t),
                                            clip.frame(t).instance_map, PUPPET_ID)[1].sum()
                           for t in range(clip.num_frames)]
    assert min(visible_counts) < 8 and max(visible_counts) == len(SKELETON_JOINTS)


@pytest.mark.parametrize("spec", DEFAULT_SPEC.videos, ids=lambda v: v.video)
def test_annotated_person_is_in_full_view_at_the_start(spec):
    """Propagation starts from frame 1's pose: the person must be visible there (as in
    JHMDB); occlusion by the other person comes later in the clip."""
    clip = render_scene(spec.scene)
    visibility = [next(o.visibility for o in clip.frame(t).objects if o.id == PUPPET_ID)
                  for t in range(clip.num_frames)]
    assert visibility[0] >= 0.95, visibility[:5]


def test_synthetic_layout_is_jhmdb(tmp_path):
    env = gym.make("UniTrack/JHMDB-v0")
    base = env.unwrapped
    root = base.dataset.root
    assert base.sequence_names == sorted(v.name for v in DEFAULT_SPEC.videos)
    spec = DEFAULT_SPEC.videos[0]
    mat = loadmat(root / "joint_positions" / spec.name / "joint_positions.mat")
    assert mat["pos_img"].shape == (2, 15, spec.scene.num_frames)
    frames = sorted((root / "Rename_Images" / spec.name).glob("*.png"))
    assert frames[0].name == "00001.png" and len(frames) == spec.scene.num_frames
    np.testing.assert_allclose(base.dataset.load(spec.name).keypoints, puppet_joints(spec))
    assert JHMDBDataset(root, split="test").sequence_names == sorted(
        v.name for v in DEFAULT_SPEC.videos if v.split == 2)
    env.close()


def test_oracle_scores_one_and_results_rescore(tmp_path):
    env = gym.make("UniTrack/JHMDB-v0")
    base = env.unwrapped
    name = base.sequence_names[0]
    rewards, info = _play(env, _Oracle(env), name)
    assert len(rewards) == base.sequence_length(name)
    assert rewards[0] == 0.0 and all(r == 1.0 for r in rewards[1:])
    assert info["metrics"] == {"PCK@0.1": 1.0, "PCK@0.2": 1.0}
    base.write_episode(tmp_path)
    written = read_joint_positions(tmp_path / name / "joint_positions.mat")
    np.testing.assert_allclose(written, base.sequence.keypoints, atol=1e-4)
    assert base.score_folder(tmp_path, [name]).combined == {"PCK@0.1": 1.0, "PCK@0.2": 1.0}
    env.close()


def test_repeat_pose_matches_direct_pck_and_pools_joints(tmp_path):
    env = gym.make("UniTrack/JHMDB-v0")
    base = env.unwrapped
    agent = make_agent("repeat-pose")
    per_video, counts = {}, None
    for name in base.sequence_names:
        rewards, info = _play(env, agent, name)
        gt = base.sequence.keypoints
        expected = pck_counts(np.repeat(gt[:1], len(gt), axis=0), gt)
        assert info["metrics"] == expected.as_dict()
        assert 0.0 < info["metrics"]["PCK@0.1"] < info["metrics"]["PCK@0.2"] < 1.0
        per_video[name] = info["metrics"]
        counts = expected if counts is None else counts.merge(expected)
        base.write_episode(tmp_path)
    report = base.score_folder(tmp_path, base.sequence_names)
    assert report.per_sequence == per_video
    assert report.combined == counts.as_dict()
    env.close()


@pytest.mark.parametrize("action", [
    np.zeros((14, 2), np.float32),
    np.full((15, 2), np.nan, np.float32),
    np.array([["a", "b"]] * 15),
])
def test_invalid_actions_raise(action):
    env = gym.make("UniTrack/JHMDB-v0")
    env.reset(seed=0)
    with pytest.raises(InvalidActionError):
        env.step(action)
    assert env.unwrapped.episode_results().shape == (0, 15, 2)
    env.close()


def test_render_draws_the_prediction():
    env = gym.make("UniTrack/JHMDB-v0", render_mode="rgb_array")
    observation, _ = env.reset(seed=0)
    env.step(observation["init_keypoints"] + 5.0)
    image = env.render()
    assert image.shape == observation["frame"].shape
    assert np.count_nonzero(np.any(image != env.unwrapped._frame, axis=2)) > 100
    env.close()


def test_real_catch_video_repeat_pose(shared_data):
    env = gym.make("UniTrack/JHMDB-v0", root=shared_data / "JHMDB")
    base = env.unwrapped
    assert base.sequence_names == [CATCH] and base.sequence_length(CATCH) == 40
    rewards, info = _play(env, make_agent("repeat-pose"), CATCH)
    assert len(rewards) == 40 and rewards[0] == 0.0
    metrics = info["metrics"]
    # Recorded floor on the real clip: the goalkeeper dives, so standing still scores ~0
    # (1 of 585 joint instances within 0.1, 9 within 0.2).
    assert metrics["PCK@0.1"] == pytest.approx(1 / 585)
    assert metrics["PCK@0.2"] == pytest.approx(9 / 585)
    env.close()
