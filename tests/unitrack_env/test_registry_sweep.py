"""Every registered id behaves like a Gymnasium env: check_env, seeds, render, pickling.

New environments are covered automatically once their row is in the registration table.
"""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import unitrack_env

ALL_IDS = unitrack_env.env_ids()


def _assert_same(a, b):
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            _assert_same(a[key], b[key])
    else:
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_check_env(env_id):
    env = gym.make(env_id, render_mode="rgb_array").unwrapped
    check_env(env, skip_render_check=False)
    env.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_same_seed_same_episode_and_pickle_roundtrip(env_id):
    env = gym.make(env_id, shuffle=True)
    first = env.reset(seed=3)
    second = env.reset(seed=3)
    assert first[1]["sequence"] == second[1]["sequence"]
    _assert_same(first[0], second[0])
    clone = pickle.loads(pickle.dumps(env))
    third = clone.reset(seed=3)
    _assert_same(first[0], third[0])
    for key in ("sequence", "frame_index", "seq_length", "frame_rate", "image_size"):
        assert key in first[1], f"{env_id}: reset info lacks '{key}'"
    env.close()
    clone.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_render_returns_an_rgb_frame(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    image = env.render()
    assert isinstance(image, np.ndarray) and image.dtype == np.uint8 and image.ndim == 3
    assert image.shape[2] == 3
    env.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_results_contract(env_id, tmp_path):
    env = gym.make(env_id)
    base = env.unwrapped
    name = base.sequence_names[0]
    assert base.sequence_length(name) >= 1
    observation, info = env.reset(options={"sequence": name})
    env.action_space.seed(0)
    action = env.action_space.sample()
    if isinstance(action, dict):  # keep padded variable-count actions small (fast scoring)
        action = {k: min(v, 3) if k.startswith("num_") else v for k, v in action.items()}
    terminated, steps = False, 0
    while not terminated:
        observation, _, terminated, truncated, info = env.step(action)
        steps += 1
        assert not truncated
    assert steps == base.sequence_length(name)
    assert len(base.episode_digest()) == 64
    base.write_episode(tmp_path)
    assert any(tmp_path.iterdir())
    if base.has_ground_truth(name):
        assert "metrics" in info
        report = base.score_folder(tmp_path, [name])
        assert set(report.per_sequence) == {name} and report.combined
    env.close()


def _first(batch, index=0):
    """Environment ``index``'s part of a batched observation (dicts, arrays or tuples)."""
    if isinstance(batch, dict):
        return {key: _first(value, index) for key, value in batch.items()}
    return batch[index]


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_async_vector_env_with_shared_memory(env_id):
    from gymnasium.vector.utils import concatenate, create_empty_array

    envs = gym.make_vec(env_id, num_envs=2, vectorization_mode="async")  # shared memory on
    single = gym.make(env_id)
    try:
        observation, _ = envs.reset(seed=0)
        expected, _ = single.reset(seed=0)
        _assert_same(_first(observation), expected)
        single.action_space.seed(0)
        action = single.action_space.sample()  # narrowed to this episode by the env
        if isinstance(action, dict):
            action = {k: min(v, 3) if k.startswith("num_") else v for k, v in action.items()}
        space = envs.single_action_space
        batch = concatenate(space, [action, action], create_empty_array(space, n=2))
        for _ in range(2):
            observation, reward, *_ = envs.step(batch)
            expected, expected_reward, *_ = single.step(action)
            _assert_same(_first(observation, 1), expected)
            assert reward[1] == pytest.approx(expected_reward)
    finally:
        envs.close()
        single.close()


@pytest.mark.parametrize("env_id", [i for i in ALL_IDS if unitrack_env.variant(i).folder])
def test_registered_data_folder_is_the_one_the_env_reads(env_id, tmp_path, monkeypatch):
    from unitrack_env.roots import DataRootNotFound

    monkeypatch.setenv("UNITRACK_DATA", str(tmp_path))
    with pytest.raises(DataRootNotFound) as missing:
        gym.make(env_id)
    assert missing.value.path == tmp_path / unitrack_env.variant(env_id).folder


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_reset_info_names_task_and_capacities(env_id):
    """Agents read their task and size limits from the reset info instead of sniffing keys."""
    env = gym.make(env_id)
    try:
        _, info = env.reset(seed=0)
        assert info["task"] == unitrack_env.task_of(env_id)
        base = env.unwrapped
        expected = {k: getattr(base, k) for k in ("max_tracks", "max_detections", "max_people",
                                                      "max_queries")
                    if hasattr(base, k)}
        assert info["capacities"] == expected
        if "max_tracks" in expected:
            assert base.action_space["ids"].shape[0] == expected["max_tracks"]
    finally:
        env.close()
