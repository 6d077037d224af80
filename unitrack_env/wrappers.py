"""Gymnasium wrappers for concerns that cut across the environments.

>>> import gymnasium as gym
>>> import unitrack_env
>>> from unitrack_env.wrappers import FrameSkip
>>> env = FrameSkip(gym.make("UniTrack/MOT17-v0"), 2)
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np


def _indexes_detections(action_space: gym.Space) -> bool:
    """Whether an action names detections by position (``{"ids": one per detection}``)."""
    return isinstance(action_space, gym.spaces.Dict) and set(action_space.spaces) == {"ids"}


def _reveals_queries(observation: Any) -> bool:
    """Whether an observation reveals new point queries (TAP-Vid's ``num_new`` > 0)."""
    return isinstance(observation, dict) and int(observation.get("num_new", 0)) > 0


class FrameSkip(gym.Wrapper):
    """The agent answers every ``skip``-th frame; the frames between are answered for it.

    Each ``step`` plays up to ``skip`` frames and returns the last observation, the summed
    reward and the last info (``info["frames_played"]``). Every frame is recorded and scored,
    so a frame-skipping tracker gets the official metrics of the whole sequence. The filler
    repeats the agent's last answer, except where an answer names detections by position
    (MOTS and VIS ids), where it reports nothing.

    A frame that reveals point queries (TAP-Vid's ``num_new`` > 0, also in the reversed pass
    of ``"strided"`` queries) is never skipped: the step ends there and the agent is shown
    it. A TAP-Vid query ``(t, y, x)`` is a position on frame ``t``, so a tracker must see
    frame ``t`` to start on it; the filler never answers for a query the agent has not been
    shown. The next step counts ``skip`` frames from there.
    """

    def __init__(self, env: gym.Env, skip: int) -> None:
        super().__init__(env)
        if int(skip) != skip or skip < 1:
            raise ValueError(f"skip must be a whole number >= 1; got {skip!r}")
        self.skip = int(skip)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Play the agent's answer, then fill in up to ``skip - 1`` frames."""
        observation, reward, terminated, truncated, info = self.env.step(action)
        total, played = float(reward), 1
        filler = self._filler(action)
        while played < self.skip and not (terminated or truncated
                                          or _reveals_queries(observation)):
            observation, reward, terminated, truncated, info = self.env.step(filler)
            total += float(reward)
            played += 1
        return observation, total, terminated, truncated, {**info, "frames_played": played}

    def _filler(self, action: Any) -> Any:
        if _indexes_detections(self.action_space):
            return {"ids": np.zeros(self.action_space["ids"].shape[0], dtype=np.int64)}
        return action
