"""Category gating for association: a track only ever matches detections of its class.

:class:`CategoryGatedAssociator` runs one
:class:`~unitrack_env.agents.primitives.association.Associator` per class (YouTube-VIS has
40) and numbers all tracks with one id sequence, in the order they are confirmed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Generic

import numpy as np

from .association import Associator, SimilarityFn
from .association_config import AssociationConfig
from .tracks import P, TrackOutput


class CategoryGatedAssociator(Generic[P]):
    """One :class:`Associator` per category, with ids shared across categories.

    Example:
        >>> same = lambda a, b: np.ones((len(a), len(b)))
        >>> gated = CategoryGatedAssociator(same)
        >>> box = np.array([[0.0, 0.0, 10.0, 20.0]] * 2)
        >>> out = gated.step(box, np.array([0.9, 0.9]), ["a", "b"], np.array([1, 2]))
        >>> [(o.track_id, o.detection_index) for o in out]   # same box, two classes: two tracks
        [(1, 0), (2, 1)]
    """

    def __init__(
        self,
        similarity: SimilarityFn | None,
        config: AssociationConfig | None = None,
        frame_rate: float = 30.0,
    ) -> None:
        self.similarity = similarity
        self.config = config if config is not None else AssociationConfig()
        self._factory: Callable[[], Associator[P]] = lambda: Associator(
            self.similarity, self.config, self._frame_rate
        )
        self._frame_rate = 30.0
        self._per_class: dict[int, Associator[P]] = {}
        self._ids: dict[tuple[int, int], int] = {}
        self._frame = 0
        self.reset(frame_rate)

    def reset(self, frame_rate: float | None = None) -> None:
        """Forget every track of every class and restart ids at 1."""
        if frame_rate is not None:
            # Validate through an Associator so that the error message is the same.
            Associator(None, self.config, frame_rate)
            self._frame_rate = float(frame_rate)
        self._per_class = {}
        self._ids = {}
        self._frame = 0

    @property
    def frame_rate(self) -> float:
        """Frames per second used for the lost-track age."""
        return self._frame_rate

    @property
    def max_lost_frames(self) -> int:
        """Frames a lost track is kept: ``round(lost_seconds * frame_rate)``."""
        return int(round(self.config.lost_seconds * self._frame_rate))

    @property
    def categories(self) -> list[int]:
        """Categories seen since the last reset, ascending."""
        return sorted(self._per_class)

    def associator(self, category: int) -> Associator[P]:
        """The engine of one category (created on first use, caught up to the frame count)."""
        engine = self._per_class.get(category)
        if engine is None:
            engine = self._factory()
            # A class first seen on frame k behaves as if it had seen k - 1 empty frames
            # (so confirm_on_first_frame only applies to the episode's first frame).
            for _ in range(self._frame):
                engine.step(np.zeros((0, 4)), np.zeros(0), [])
            self._per_class[category] = engine
        return engine

    def step(
        self,
        boxes: np.ndarray,
        scores: np.ndarray,
        payloads: Sequence[P],
        categories: Any,
    ) -> list[TrackOutput]:
        """Associate one frame's detections, each only with tracks of its integer ``categories``.

        Returns the confirmed tracks matched in this frame, ids unique across categories, by id.
        """
        boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        scores = np.asarray(scores, dtype=np.float64).reshape(-1)
        cats = np.asarray(categories).reshape(-1)
        if not (len(boxes) == len(scores) == len(payloads) == len(cats)):
            raise ValueError(
                f"got {len(boxes)} boxes, {len(scores)} scores, {len(payloads)} payloads and "
                f"{len(cats)} categories; they must have the same length"
            )
        if cats.size and not np.issubdtype(cats.dtype, np.integer):
            raise ValueError(f"categories must be integers, got dtype {cats.dtype}")
        for category in sorted({int(c) for c in cats.tolist()}):
            self.associator(category)  # create engines before stepping (frame count)
        self._frame += 1
        outputs = []
        for category, engine in sorted(self._per_class.items()):
            index = np.flatnonzero(cats == category)
            for out in engine.step(boxes[index], scores[index], [payloads[i] for i in index]):
                key = (category, out.track_id)
                if key not in self._ids:
                    self._ids[key] = len(self._ids) + 1
                outputs.append(TrackOutput(self._ids[key], out.box, out.score,
                                           int(index[out.detection_index])))
        outputs.sort(key=lambda o: o.track_id)
        return outputs
