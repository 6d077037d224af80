"""Spaces shared by the environments, and helpers to build valid actions.

Why padded arrays plus a count instead of ``gymnasium.spaces.Sequence``: a frame holds a
variable number of detections and tracks; fixed-capacity arrays keep every observation a
plain dict of numpy arrays (cheap to copy, batch, pickle and check), and ``check_env``
accepts them. The capacity is a constructor argument of each environment.

Why a custom :class:`Image` space instead of a fixed ``Box``: tracking benchmarks mix frame
sizes (MOT17 has 1920x1080 and 640x480 sequences). Resizing would change the benchmark's
geometry and padding every frame to the largest size would waste memory and time, so a
frame keeps its native size and the space bounds it instead.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from unitrack_env.errors import InvalidActionError


class Image(spaces.Space[np.ndarray]):
    """A ``uint8`` image of shape ``(H, W, channels)`` whose size may vary between episodes.

    Args:
        max_height: largest accepted height.
        max_width: largest accepted width.
        channels: number of channels (3 for RGB).
        seed: seed of the space's own random generator (used by :meth:`sample`).
    """

    def __init__(
        self, max_height: int, max_width: int, channels: int = 3, seed: int | None = None
    ) -> None:
        if max_height < 1 or max_width < 1 or channels < 1:
            raise ValueError("Image space bounds must be positive")
        self.max_height = int(max_height)
        self.max_width = int(max_width)
        self.channels = int(channels)
        super().__init__(shape=None, dtype=np.uint8, seed=seed)

    @property
    def is_np_flattenable(self) -> bool:
        """Images of varying size cannot be flattened to one fixed vector."""
        return False

    def sample(self, mask: Any = None, probability: Any = None) -> np.ndarray:
        """Return a random image of random size within the bounds."""
        if mask is not None or probability is not None:
            raise NotImplementedError("Image.sample does not support masks")
        height = int(self.np_random.integers(1, min(self.max_height, 64) + 1))
        width = int(self.np_random.integers(1, min(self.max_width, 64) + 1))
        return self.np_random.integers(0, 256, (height, width, self.channels), dtype=np.uint8)

    def contains(self, x: Any) -> bool:
        """Whether ``x`` is a ``uint8`` image within the bounds."""
        return (
            isinstance(x, np.ndarray)
            and x.dtype == np.uint8
            and x.ndim == 3
            and x.shape[2] == self.channels
            and 1 <= x.shape[0] <= self.max_height
            and 1 <= x.shape[1] <= self.max_width
        )

    def __repr__(self) -> str:
        return (f"Image(max_height={self.max_height}, max_width={self.max_width}, "
                f"channels={self.channels})")

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Image)
            and other.max_height == self.max_height
            and other.max_width == self.max_width
            and other.channels == self.channels
        )

    def to_jsonable(self, sample_n: Sequence[np.ndarray]) -> list:
        """Convert a batch of images to lists."""
        return [image.tolist() for image in sample_n]

    def from_jsonable(self, sample_n: Sequence[Any]) -> list[np.ndarray]:
        """Convert lists back to images."""
        return [np.asarray(image, dtype=np.uint8) for image in sample_n]


#: Largest finite float32: "any finite number" bounds (infinite bounds would accept NaN-free
#: infinities and make ``check_env`` warn).
FLOAT_MAX = float(np.finfo(np.float32).max)
#: Bound of box coordinates in pixels (generous: boxes may extend past the frame).
COORD_MAX = 1e5


def box_array_space(capacity: int) -> spaces.Box:
    """``(capacity, 4)`` float32 boxes ``(x, y, w, h)``: finite, ``w, h >= 0``; padding is 0."""
    low = np.tile(np.array([-COORD_MAX, -COORD_MAX, 0.0, 0.0], np.float32), (capacity, 1))
    return spaces.Box(low, np.float32(COORD_MAX), (capacity, 4), np.float32)


def detection_observation_space(
    max_detections: int, max_frame_size: tuple[int, int]
) -> spaces.Dict:
    """Observation space of box association tasks (see ``docs/architecture.md``)."""
    return spaces.Dict(
        {
            "frame": Image(*max_frame_size),
            "boxes": box_array_space(max_detections),
            "scores": spaces.Box(-FLOAT_MAX, FLOAT_MAX, (max_detections,), np.float32),
            "num_detections": spaces.Discrete(max_detections + 1),
        }
    )


def track_action_space(max_tracks: int) -> spaces.Dict:
    """Action space of box association tasks: padded ``ids``/``boxes`` and ``num_tracks``."""
    return spaces.Dict(
        {
            "ids": spaces.Box(1, np.iinfo(np.int32).max, (max_tracks,), np.int64),
            "boxes": box_array_space(max_tracks),
            "num_tracks": spaces.Discrete(max_tracks + 1),
        }
    )


def pack_tracks(ids: Any, boxes: Any, max_tracks: int) -> dict[str, Any]:
    """Build a padded track action from ``k`` ids and ``(k, 4)`` boxes.

    >>> action = pack_tracks([3, 7], [[0, 0, 10, 20], [5, 5, 10, 20]], max_tracks=4)
    >>> action["num_tracks"], action["ids"].tolist()
    (2, [3, 7, 0, 0])
    """
    ids_arr = np.asarray(ids, dtype=np.int64).reshape(-1)
    boxes_arr = np.asarray(boxes, dtype=np.float32).reshape(-1, 4)
    k = len(ids_arr)
    if len(boxes_arr) != k:
        raise InvalidActionError(f"{k} ids but {len(boxes_arr)} boxes")
    if k > max_tracks:
        raise InvalidActionError(
            f"{k} tracks exceed the action capacity max_tracks={max_tracks}; "
            "raise max_tracks when making the environment"
        )
    out_ids = np.zeros(max_tracks, dtype=np.int64)
    out_boxes = np.zeros((max_tracks, 4), dtype=np.float32)
    out_ids[:k] = ids_arr
    out_boxes[:k] = boxes_arr
    return {"ids": out_ids, "boxes": out_boxes, "num_tracks": k}


def unpack_detections(observation: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Return the valid ``(boxes (n, 4), scores (n,))`` of a detection observation."""
    n = int(observation["num_detections"])
    return observation["boxes"][:n], observation["scores"][:n]


def unpack_tracks(
    action: dict[str, Any], max_tracks: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Validate a track action and return ``(ids (k,) int64, boxes (k, 4) float64)``.

    Accepts the padded form (with ``num_tracks``) or the unpadded ``{"ids", "boxes"}``.

    Raises:
        InvalidActionError: wrong keys, shapes or dtypes; NaN/inf or negative sizes;
            ids that are not positive integers or repeat.
    """
    if not isinstance(action, dict) or "ids" not in action or "boxes" not in action:
        raise InvalidActionError(
            "action must be a dict with 'ids' and 'boxes' (and optionally 'num_tracks'); "
            "build one with unitrack_env.spaces.pack_tracks(ids, boxes, max_tracks)"
        )
    ids = np.asarray(action["ids"])
    boxes = np.asarray(action["boxes"])
    if ids.ndim != 1:
        raise InvalidActionError(f"action['ids'] must be 1-D, got shape {ids.shape}")
    if boxes.ndim != 2 or boxes.shape[1] != 4:
        raise InvalidActionError(f"action['boxes'] must have shape (k, 4), got {boxes.shape}")
    if not np.issubdtype(ids.dtype, np.integer):
        if ids.size and not (np.issubdtype(ids.dtype, np.floating)
                             and np.all(np.isfinite(ids)) and np.all(ids == np.round(ids))):
            raise InvalidActionError(f"action['ids'] must be integers, got dtype {ids.dtype}")
    if not (np.issubdtype(boxes.dtype, np.floating) or np.issubdtype(boxes.dtype, np.integer)):
        raise InvalidActionError(f"action['boxes'] must be numbers, got dtype {boxes.dtype}")
    if "num_tracks" in action:
        k = int(action["num_tracks"])
        if not 0 <= k <= min(len(ids), len(boxes)):
            raise InvalidActionError(
                f"num_tracks={k} but the arrays hold {len(ids)} ids and {len(boxes)} boxes"
            )
    else:
        k = len(ids)
        if len(boxes) != k:
            raise InvalidActionError(f"{k} ids but {len(boxes)} boxes")
    if max_tracks is not None and k > max_tracks:
        raise InvalidActionError(f"{k} tracks exceed max_tracks={max_tracks}")
    ids = ids[:k].astype(np.int64)
    boxes = boxes[:k].astype(np.float64)
    if not np.all(np.isfinite(boxes)):
        row = int(np.argwhere(~np.isfinite(boxes))[0, 0])
        raise InvalidActionError(f"track {ids[row]} has a non-finite box {boxes[row].tolist()}")
    negative = (boxes[:, 2] < 0) | (boxes[:, 3] < 0)
    if negative.any():
        row = int(np.argmax(negative))
        raise InvalidActionError(f"track {ids[row]} has a negative size {boxes[row].tolist()}")
    if k and ids.min() < 1:
        raise InvalidActionError(f"track ids must be >= 1, got {int(ids.min())}")
    if k != len(np.unique(ids)):
        values, counts = np.unique(ids, return_counts=True)
        raise InvalidActionError(f"duplicate track ids in one frame: {values[counts > 1].tolist()}")
    return ids, boxes
