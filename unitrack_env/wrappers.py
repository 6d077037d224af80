"""Gymnasium wrappers for concerns that cut across the environments.

:class:`FrameSkip` lets the agent answer every ``k``-th frame only; the environment still
plays and scores every frame, so the final ``info["metrics"]`` are the official metrics of
the whole sequence. (Which detections an agent sees is the association environments'
``min_score=`` argument, the one place that filters them.)

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


class FrameSkip(gym.Wrapper):
    """The agent answers every ``skip``-th frame; the frames between are answered for it.

    Each ``step`` plays ``skip`` frames of the environment: the agent's answer for the
    current frame, then a filler answer for each of the next ``skip - 1`` frames, and
    returns the observation of the frame after them, the sum of the rewards and the last
    info (with ``info["frames_played"]``). The environment records and scores every frame,
    so ``write_episode`` and the final ``info["metrics"]`` cover the whole sequence with the
    official metrics: a frame-skipping tracker is scored exactly like any other.

    The filler holds the agent's last answer (the same tracks, box, label map or joints)
    where an answer does not depend on the frame, and reports nothing where it names the
    frame's detections by position (MOTS and VIS ``{"ids": ...}``: ids of one frame's
    detections mean nothing on another frame).

    Args:
        env: any unitrack environment.
        skip: frames per agent step (1: no skipping).
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
        while played < self.skip and not (terminated or truncated):
            observation, reward, terminated, truncated, info = self.env.step(filler)
            total += float(reward)
            played += 1
        return observation, total, terminated, truncated, {**info, "frames_played": played}

    def _filler(self, action: Any) -> Any:
        if _indexes_detections(self.action_space):
            return {"ids": np.zeros(self.action_space["ids"].shape[0], dtype=np.int64)}
        return action
