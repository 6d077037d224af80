"""Propagation floors: agents that answer every frame with the first frame's target.

A tracker that never moves scores what the target's own stillness gives for free: on a
sequence where the target stays put (DAVIS blackswan) that is a lot, on one where it walks
away (OTB Human3) almost nothing. Any propagation agent must beat these numbers to show it
tracks at all.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..base import Agent

#: DAVIS's void label; it marks ambiguous pixels of the ground truth and is no prediction.
VOID_LABEL = 255


class RepeatBoxAgent(Agent, name="repeat-box", tasks=("sot",)):
    """Answers every frame with the initial box (``observation["init_box"]``)."""

    def __init__(self) -> None:
        self._box: np.ndarray | None = None

    def reset(self, observation: Any, info: dict[str, Any]) -> None:
        """Remember the first frame's box."""
        self._box = np.array(observation["init_box"], dtype=np.float32)

    def act(self, observation: Any) -> np.ndarray:
        """Return the first frame's box."""
        if self._box is None:
            raise RuntimeError("call reset() with the first observation before act()")
        return self._box.copy()


class RepeatMaskAgent(Agent, name="repeat-mask", tasks=("vos",)):
    """Answers every frame with the first frame's label map (void pixels become background)."""

    def __init__(self) -> None:
        self._labels: np.ndarray | None = None

    def reset(self, observation: Any, info: dict[str, Any]) -> None:
        """Remember the first frame's label map, with void (255) set to background (0)."""
        labels = np.array(observation["init_labels"], dtype=np.uint8)
        labels[labels == VOID_LABEL] = 0
        self._labels = labels

    def act(self, observation: Any) -> np.ndarray:
        """Return the first frame's label map."""
        if self._labels is None:
            raise RuntimeError("call reset() with the first observation before act()")
        return self._labels.copy()
