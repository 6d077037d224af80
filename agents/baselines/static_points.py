"""A point tracking baseline that never moves: each point stays at its query position."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..base import Agent
from ..primitives.point_queries import QueryBook


class StaticPointsAgent(Agent, name="static-points", tasks=("points",)):
    """Answers every frame with each query's own position, always visible.

    It looks at no pixels: its scores measure how much the points move (and how often they
    are occluded), the floor a point tracker has to beat.
    """

    def __init__(self) -> None:
        self.book = QueryBook()

    def reset(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        """Start an episode."""
        self.book.reset(info)

    def act(self, observation: dict[str, Any]) -> dict[str, np.ndarray]:
        """Every known query at its query position, visible."""
        self.book.update(observation)
        return self.book.action()
