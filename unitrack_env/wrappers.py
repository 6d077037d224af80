"""Gymnasium wrappers for concerns that cut across the environments.

Each wrapper works on every environment it fits, instead of a flag on each environment:

- :class:`DetectionScoreFilter` drops the detections (boxes, masks or poses) scored below a
  threshold from the observations of an association environment (MOT, MOTS, VIS,
  PoseTrack). It replaces the environments' ``min_score=`` argument, which still works.
- :class:`FrameSkip` lets the agent answer every ``k``-th frame only; the environment still
  plays and scores every frame, so the final ``info["metrics"]`` are the official metrics of
  the whole sequence.

>>> import gymnasium as gym
>>> import unitrack_env
>>> from unitrack_env.wrappers import DetectionScoreFilter, FrameSkip
>>> env = FrameSkip(DetectionScoreFilter(gym.make("UniTrack/MOT17-v0"), 0.5), 2)
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from unitrack_env import spaces as ut_spaces

#: Observation keys that hold the number of valid detection rows, by task family.
COUNT_KEYS = ("num_detections", "num_people")
#: Padded per-detection observation arrays (one row per detection, then zeros).
PADDED_KEYS = ("boxes", "scores", "classes", "keypoints")
#: Per-detection arrays with exactly one entry per detection (no padding).
STACKED_KEYS = ("masks",)


def _count_key(observation: dict[str, Any]) -> str:
    for key in COUNT_KEYS:
        if key in observation:
            return key
    raise TypeError(f"the observation has no detections to filter (none of {COUNT_KEYS}); "
                    "DetectionScoreFilter wraps the association environments")


def _indexes_detections(action_space: gym.Space) -> bool:
    """Whether an action names detections by position (``{"ids": one per detection}``)."""
    return isinstance(action_space, gym.spaces.Dict) and set(action_space.spaces) == {"ids"}


class DetectionScoreFilter(gym.Wrapper):
    """Drop the detections scored below ``min_score`` from every observation.

    The kept detections keep their order and the padded arrays their capacity, so the
    observation stays in the environment's observation space. Where the action gives a
    track id per detection (MOTS and VIS: ``{"ids": ...}``), the agent answers for the kept
    detections and the wrapper hands the environment one id per original detection (0, not
    reported, for the dropped ones); box and pose track actions pass through unchanged.

    The result equals the environments' ``min_score=`` argument, except that the capacity
    check at reset (``max_detections``) counts every detection and the reset picture of
    ``render()`` shows every detection.

    Args:
        env: an association environment (its observations have ``scores`` and
            ``num_detections`` or ``num_people``).
        min_score: the lowest score kept.
    """

    def __init__(self, env: gym.Env, min_score: float) -> None:
        super().__init__(env)
        self.min_score = float(min_score)
        self._keep: np.ndarray = np.zeros(0, dtype=bool)

    def reset(self, **kwargs: Any) -> tuple[dict[str, Any], dict[str, Any]]:
        """Reset the environment and filter the first observation."""
        observation, info = self.env.reset(**kwargs)
        return self._filter(observation), info

    def step(self, action: Any) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        """Pass the action on (ids re-indexed to every detection) and filter what comes back."""
        if _indexes_detections(self.action_space):
            action = self._expand(action)
        observation, reward, terminated, truncated, info = self.env.step(action)
        return self._filter(observation), reward, terminated, truncated, info

    def _filter(self, observation: dict[str, Any]) -> dict[str, Any]:
        count = _count_key(observation)
        n = int(observation[count])
        self._keep = np.asarray(observation["scores"][:n]) >= self.min_score
        kept = int(self._keep.sum())
        out = dict(observation)
        for key in PADDED_KEYS:
            if key in observation:
                array = np.zeros_like(observation[key])
                array[:kept] = observation[key][:n][self._keep]
                out[key] = array
        for key in STACKED_KEYS:
            if key in observation:
                out[key] = np.ascontiguousarray(observation[key][self._keep])
        out[count] = kept
        return out

    def _expand(self, action: Any) -> dict[str, np.ndarray]:
        capacity = self.action_space["ids"].shape[0]
        ids = ut_spaces.unpack_mask_ids(action, int(self._keep.sum()), capacity)
        full = np.zeros(len(self._keep), dtype=np.int64)
        full[self._keep] = ids
        return {"ids": full}


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
