"""Every registered agent plays every registered environment of the tasks it claims.

A new agent (or a new environment row) is covered automatically: the pairs come from the
agent registry (``agent.tasks``) and the registration table (``task_of``). Each pair plays a
few frames of the embedded synthetic data; every action must lie in the action space and be
accepted by the environment. The appearance heads share one model and run on small inputs
so that the sweep stays fast.
"""

from __future__ import annotations

import inspect
from typing import Any

import gymnasium as gym
import pytest

import unitrack_env
from unitrack_env.agents import agent_class, available_agents

#: Frames played per pair (the first one is the reset frame).
STEPS = 3

#: Options that keep the appearance heads fast (small inputs, one thread, no disk cache).
FAST_OPTIONS: dict[str, dict[str, Any]] = {
    "unitrack": {"input_size": (272, 152), "feature_cache": False, "num_threads": 1},
    "unitrack-pose": {"input_size": (160, 160), "num_threads": 1},
    "unitrack-vos": {"num_threads": 1},
    "unitrack-xcorr": {"num_threads": 1},
    "unitrack-dcf": {"num_threads": 1},
    "unitrack-points": {"input_size": (128, 128), "feature_cache": False, "num_threads": 1},
}


def _built_in_agents() -> list[str]:
    """The agents defined in the package (plug-ins installed elsewhere are not swept)."""
    return [name for name in available_agents()
            if agent_class(name).__module__.startswith("unitrack_env.agents.")]


PAIRS = [
    pytest.param(name, env_id, id=f"{name}-{env_id.split('/')[-1]}")
    for name in _built_in_agents()
    for env_id in unitrack_env.env_ids()
    if unitrack_env.task_of(env_id) in agent_class(name).tasks
]


@pytest.fixture(scope="module")
def model():
    """One appearance model shared by the heads (built once)."""
    from unitrack_env.agents.appearance import AppearanceModel

    return AppearanceModel(num_threads=1)


def _make(name: str, model: Any) -> Any:
    cls = agent_class(name)
    options = dict(FAST_OPTIONS.get(name, {}))
    if "appearance_model" in inspect.signature(cls.__init__).parameters:
        options["appearance_model"] = model
    return cls(**options)


def test_every_agent_claims_a_registered_task() -> None:
    tasks = {unitrack_env.task_of(env_id) for env_id in unitrack_env.env_ids()}
    for name in _built_in_agents():
        assert set(agent_class(name).tasks) <= tasks, name
        assert agent_class(name).tasks, f"{name} claims no task"


@pytest.mark.parametrize(("name", "env_id"), PAIRS)
def test_agent_plays_env(name: str, env_id: str, model: Any) -> None:
    env = gym.make(env_id)
    try:
        agent = _make(name, model)
        base = env.unwrapped
        obs, info = env.reset(options={"sequence": base.sequence_names[0]})
        assert info["task"] == unitrack_env.task_of(env_id)
        agent.reset(obs, info)
        for _ in range(STEPS):
            action = agent.act(obs)
            assert env.action_space.contains(action), f"{name} on {env_id}: {action!r}"
            obs, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        agent.close()
    finally:
        env.close()
