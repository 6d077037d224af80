"""What a point tracking agent knows of its queries: ids, last positions, flags, passes.

The point tracking environments (``UniTrack/TAPVid-*``) reveal each query at its frame and
ask for every active query's position and occlusion flag; a strided episode replays the
video backwards in a second pass (``observation["reverse"]``), where every query starts
again from its query point. :class:`QueryBook` keeps that state and builds the action.
"""

from __future__ import annotations

from typing import Any

import numpy as np


class QueryBook:
    """The queries of one episode, by id: position ``(x, y)`` and predicted occlusion."""

    def __init__(self) -> None:
        self.capacity = 0
        self.positions = np.zeros((0, 2))
        self.occluded = np.zeros(0, bool)
        self.known = np.zeros(0, bool)
        self.reverse = False

    def reset(self, info: dict[str, Any]) -> None:
        """Size the book for an episode (``info["capacities"]["max_queries"]``)."""
        self.capacity = int(info["capacities"]["max_queries"])
        self.positions = np.zeros((self.capacity, 2))
        self.occluded = np.zeros(self.capacity, bool)
        self.known = np.zeros(self.capacity, bool)
        self.reverse = False

    def update(self, observation: dict[str, Any]) -> tuple[np.ndarray, bool]:
        """Take in a step's new queries; return their ids and whether a new pass started.

        At the start of the reversed pass every query is forgotten: it is revealed again.
        """
        reverse = bool(observation["reverse"])
        restarted = reverse != self.reverse
        if restarted:
            self.reverse = reverse
            self.known[:] = False
        count = int(observation["num_new"])
        ids = np.asarray(observation["query_ids"][:count], np.int64)
        self.positions[ids] = np.asarray(observation["query_points"][:count], np.float64)
        self.occluded[ids] = False
        self.known[ids] = True
        return ids, restarted

    def active(self, observation: dict[str, Any]) -> np.ndarray:
        """Ids of the queries answered at this step that the book knows."""
        return np.flatnonzero(np.asarray(observation["active"], bool) & self.known)

    def action(self) -> dict[str, np.ndarray]:
        """The action: every query's position and flag (unknown rows are ignored)."""
        return {"tracks": self.positions.astype(np.float32),
                "occluded": self.occluded.astype(np.int8)}
