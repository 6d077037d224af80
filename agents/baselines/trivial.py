"""A deliberately weak agent that gives the metrics a floor."""

from __future__ import annotations

from typing import Any

import numpy as np

from unitrack_env.spaces.boxes import pack_tracks, unpack_detections

from ..base import Agent


class FreshIdsAgent(Agent, name="fresh-ids", tasks=("mot",)):
    """Reports every detection as a new track with a never-seen id.

    Nothing is associated, so every continuing object is an identity switch: the floor for
    IDF1, AssA and HOTA. ``max_tracks`` must match the environment's.
    """

    def __init__(self, max_tracks: int = 512) -> None:
        self.max_tracks = max_tracks
        self._next_id = 1

    def reset(self, observation: Any, info: dict[str, Any]) -> None:
        """Restart ids at 1."""
        self._next_id = 1

    def act(self, observation: dict[str, Any]) -> dict[str, Any]:
        """Give each detection a fresh id."""
        boxes, _ = unpack_detections(observation)
        ids = np.arange(self._next_id, self._next_id + len(boxes))
        self._next_id += len(boxes)
        return pack_tracks(ids, boxes, self.max_tracks)
