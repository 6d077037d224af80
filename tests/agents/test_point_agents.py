"""Point tracking agents: static-points, lk-points and unitrack-points (with its golden)."""

from __future__ import annotations

from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np
import pytest

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.agents import make_agent

GOLDENS = Path(__file__).resolve().parents[1] / "goldens"
INFO = {"capacities": {"max_queries": 4}}


def _observation(frame, ids=(), points=(), active=(), reverse=0):
    capacity = INFO["capacities"]["max_queries"]
    query_ids = np.full(capacity, -1, np.int64)
    query_points = np.zeros((capacity, 2), np.float32)
    query_ids[:len(ids)] = ids
    query_points[:len(points)] = np.reshape(points, (-1, 2))
    mask = np.zeros(capacity, np.int8)
    mask[list(active)] = 1
    return {"frame": frame, "query_ids": query_ids, "query_points": query_points,
            "num_new": len(ids), "active": mask, "reverse": reverse}


def _texture(seed=0, size=96):
    noise = np.random.default_rng(seed).uniform(0, 255, (size // 4, size // 4, 3))
    return cv2.resize(noise.astype(np.uint8), (size, size), interpolation=cv2.INTER_CUBIC)


def test_static_points_repeat_the_query_and_forget_it_in_the_reversed_pass():
    agent = make_agent("static-points")
    frame = np.zeros((8, 8, 3), np.uint8)
    agent.reset(None, INFO)
    first = agent.act(_observation(frame, [1], [[3.0, 4.0]], [1]))
    assert first["tracks"][1].tolist() == [3.0, 4.0] and first["occluded"].sum() == 0
    later = agent.act(_observation(frame, active=[1]))
    assert later["tracks"][1].tolist() == [3.0, 4.0]
    agent.act(_observation(frame, reverse=1))
    assert not agent.book.known.any()


def test_lucas_kanade_follows_a_shift_and_flags_a_vanished_point():
    texture = _texture()
    shifted = np.roll(texture, (2, 3), axis=(0, 1))  # 3 px right, 2 px down
    agent = make_agent("lk-points")
    agent.reset(None, INFO)
    agent.act(_observation(texture, [0, 1], [[48.5, 40.5], [20.5, 60.5]], [0, 1]))
    blank = shifted.copy()
    blank[45:80, 5:40] = 128  # point 1's neighbourhood becomes flat: the flow is lost
    moved = agent.act(_observation(blank, active=[0, 1]))
    assert np.allclose(moved["tracks"][0], [51.5, 42.5], atol=0.1)
    assert moved["occluded"][0] == 0 and moved["occluded"][1] == 1


def test_lucas_kanade_beats_static_points_on_the_synthetic_videos():
    """Measured AJ 0.561 against 0.436 (mean of the three synthetic TAPVid-DAVIS videos)."""
    env = gym.make("UniTrack/TAPVid-DAVIS-v0")
    scores = {}
    for name in ("static-points", "lk-points"):
        agent = make_agent(name)
        values = []
        for sequence in env.unwrapped.sequence_names:
            observation, info = env.reset(options={"sequence": sequence})
            agent.reset(observation, info)
            terminated = False
            while not terminated:
                observation, _, terminated, _, info = env.step(agent.act(observation))
            values.append(info["metrics"]["AJ"])
        scores[name] = np.mean(values)
    assert scores["lk-points"] > scores["static-points"] + 0.05, scores


def test_unitrack_points_follows_a_shifted_texture():
    texture = _texture(1, 128)
    agent = make_agent("unitrack-points", feature_cache=False, num_threads=1)
    agent.reset(None, INFO)
    agent.act(_observation(texture, [2], [[64.5, 60.5]], [2]))
    moved = agent.act(_observation(np.roll(texture, (0, 8), axis=(0, 1)), active=[2]))
    assert abs(moved["tracks"][2][0] - 72.5) < 3 and abs(moved["tracks"][2][1] - 60.5) < 3
    assert moved["occluded"][2] == 0


def test_unitrack_points_golden(episode_regression):
    episode_regression.check(
        "UniTrack/TAPVid-DAVIS-v0", agent="unitrack-points", sequence="syn-fast",
        agent_kwargs={"num_threads": 1, "feature_cache": False},
        golden=GOLDENS / "unitrack-points-TAPVid-syn-fast.json", tolerance=2e-3)


@pytest.mark.parametrize("mode", ["first", "strided"])
def test_unitrack_points_plays_both_query_modes(mode):
    env = gym.make("UniTrack/TAPVid-RGBStacking-v0", query_mode=mode)
    agent = make_agent("unitrack-points", input_size=(128, 128), feature_cache=False,
                       num_threads=1)
    observation, info = env.reset(options={"sequence": "1"})
    agent.reset(observation, info)
    terminated = False
    while not terminated:
        observation, _, terminated, _, info = env.step(agent.act(observation))
    assert 0.0 <= info["metrics"]["AJ"] <= 1.0


def test_unitrack_points_maps_the_raster_onto_a_smaller_input():
    """With ``input_size`` half the raster, a feature cell spans 16 raster pixels."""
    texture = _texture(2, 256)
    agent = make_agent("unitrack-points", input_size=(128, 128), feature_cache=False,
                       num_threads=1)
    agent.reset(None, INFO)
    agent.act(_observation(texture, [0], [[200.5, 100.5]], [0]))
    assert np.allclose(agent._scale, [1 / 16, 1 / 16])
    assert agent._groups[0].peaks[0] > 0.3  # the point's belief map lies on the grid


@pytest.mark.slow
def test_unitrack_points_beats_static_points_on_the_real_fixtures(shared_data):
    """Measured AJ ("first", 256 x 256): unitrack-points 0.355, static-points 0.103."""
    env = gym.make("UniTrack/TAPVid-DAVIS-v0", root=str(shared_data / "TAPVid"))
    scores = {}
    for name in ("static-points", "unitrack-points"):
        agent = make_agent(name)
        values = []
        for sequence in env.unwrapped.sequence_names:
            observation, info = env.reset(options={"sequence": sequence})
            agent.reset(observation, info)
            terminated = False
            while not terminated:
                observation, _, terminated, _, info = env.step(agent.act(observation))
            values.append(info["metrics"]["AJ"])
        scores[name] = np.mean(values)
    assert scores["unitrack-points"] > scores["static-points"] + 0.1, scores
