"""An appearance-free point tracker: OpenCV's pyramidal Lucas-Kanade flow (``lk-points``).

Each point moves by ``cv2.calcOpticalFlowPyrLK`` from the previous frame to this one; the
flow is run back from this frame and a point whose round trip misses its start by more than
:data:`FB_MAX_ERROR` pixels (the forward-backward check of Kalal et al., 2010), or that
OpenCV loses, is reported occluded and stays where it was.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from ..base import Agent
from ..primitives.point_queries import QueryBook

WINDOW: int = 21
"""Side of the LK search window (pixels): OpenCV's default."""

PYRAMID_LEVELS: int = 3
"""Pyramid levels above the frame: OpenCV's default."""

FB_MAX_ERROR: float = 1.0
"""Forward-backward error (pixels) above which a point counts as occluded: one pixel, the
accuracy a sub-pixel flow should reach on a point it really sees (not tuned)."""


@dataclass(frozen=True)
class LucasKanadeConfig:
    """Options of ``lk-points`` (defaults above)."""

    window: int = WINDOW
    pyramid_levels: int = PYRAMID_LEVELS
    fb_max_error: float = FB_MAX_ERROR


def _gray(frame: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(np.ascontiguousarray(frame), cv2.COLOR_RGB2GRAY)


class LucasKanadePointsAgent(Agent, name="lk-points", tasks=("points",)):
    """Pyramidal Lucas-Kanade flow per point, occlusion by the forward-backward check."""

    config_class = LucasKanadeConfig

    def __init__(self, **options: Any) -> None:
        self.config = LucasKanadeConfig(**options)
        self.book = QueryBook()
        self._previous: np.ndarray | None = None

    def reset(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        """Start an episode."""
        self.book.reset(info)
        self._previous = None

    def _flow(self, source: np.ndarray, target: np.ndarray, points: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        size = (self.config.window, self.config.window)
        moved, status, _ = cv2.calcOpticalFlowPyrLK(
            source, target, points.astype(np.float32).reshape(-1, 1, 2), None, winSize=size,
            maxLevel=self.config.pyramid_levels)
        return moved.reshape(-1, 2).astype(np.float64), status.reshape(-1).astype(bool)

    def act(self, observation: dict[str, Any]) -> dict[str, np.ndarray]:
        """Move every tracked point by the flow from the previous frame."""
        new, restarted = self.book.update(observation)
        gray = _gray(observation["frame"])
        if restarted:
            self._previous = None
        tracked = np.setdiff1d(self.book.active(observation), new)
        if self._previous is not None and len(tracked):
            # OpenCV's coordinates put a pixel's centre at i; the environment's at i + 0.5
            start = self.book.positions[tracked] - 0.5
            forward, ok = self._flow(self._previous, gray, start)
            back, ok_back = self._flow(gray, self._previous, forward)
            good = ok & ok_back & (np.linalg.norm(back - start, axis=1)
                                   <= self.config.fb_max_error)
            self.book.positions[tracked[good]] = forward[good] + 0.5
            self.book.occluded[tracked] = ~good
        self._previous = gray
        return self.book.action()
