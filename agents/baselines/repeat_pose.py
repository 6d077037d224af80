"""A pose-propagation baseline that never moves: it repeats the first frame's joints."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..base import Agent


class RepeatPoseAgent(Agent, name="repeat-pose", tasks=("pose-prop",)):
    """Answers every frame with the given first-frame joints (``init_keypoints``).

    It looks at no pixels, so its PCK measures how much the person moves: the floor a
    propagation agent has to beat (on JHMDB a person often stays roughly in place, so the
    floor is far from zero).
    """

    def __init__(self) -> None:
        self._pose: np.ndarray | None = None

    def reset(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        """Remember the episode's first-frame joints."""
        self._pose = np.array(observation["init_keypoints"], dtype=np.float32, copy=True)

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        """Return the first-frame joints again."""
        if self._pose is None:
            raise RuntimeError("call reset() before act()")
        return self._pose.copy()
