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
#: Largest track id of the action spaces. Official result files store ids as numbers that
#: are read back as floats (MOTChallenge txt) or JSON numbers; int32 ids survive every one
#: of them exactly (float64 holds integers only up to 2**53).
ID_MAX = int(np.iinfo(np.int32).max)


def _action_count(action: dict[str, Any], key: str) -> int:
    """The action's ``key`` count (``num_tracks``) as an int; refuse non-integers."""
    value = action[key]
    if isinstance(value, (bool, np.bool_)):
        raise InvalidActionError(f"action['{key}'] must be an integer, got {value!r}")
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)) and float(value).is_integer():
        return int(value)
    raise InvalidActionError(
        f"action['{key}'] must be an integer (the space is Discrete), got {value!r}")


def _number(value: Any) -> str:
    """An id as the user wrote it: exact for integers, short for huge floats."""
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return f"{float(value):.0f}" if abs(float(value)) < 1e16 else f"{float(value):g}"


def _checked_ids(ids: np.ndarray, k: int, *, low: int = 1) -> np.ndarray:
    """The first ``k`` ids as int64 after checking integer values in ``low..ID_MAX``."""
    ids = ids[:k]
    if not np.issubdtype(ids.dtype, np.integer):
        if ids.size and not (np.issubdtype(ids.dtype, np.floating)
                             and np.all(np.isfinite(ids)) and np.all(ids == np.round(ids))):
            raise InvalidActionError(f"action['ids'] must be integers, got dtype {ids.dtype}")
    if ids.size and (ids.max() > ID_MAX):
        raise InvalidActionError(
            f"track id {_number(ids.max())} is above {ID_MAX}, the largest id of the action "
            "space (ids must survive the official result files, which store them as floats)")
    if ids.size and ids.min() < low:
        what = "track ids must be >= 1" + (" (0 = not reported)" if low == 0 else "")
        raise InvalidActionError(f"{what}, got {_number(ids.min())}")
    return ids.astype(np.int64)


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
            # ids >= 1; 0 marks the padding past num_tracks
            "ids": spaces.Box(0, np.iinfo(np.int32).max, (max_tracks,), np.int64),
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
    if not (np.issubdtype(boxes.dtype, np.floating) or np.issubdtype(boxes.dtype, np.integer)):
        raise InvalidActionError(f"action['boxes'] must be numbers, got dtype {boxes.dtype}")
    if "num_tracks" in action:
        k = _action_count(action, "num_tracks")
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
    ids = _checked_ids(ids, k)
    boxes = boxes[:k].astype(np.float64)
    if not np.all(np.isfinite(boxes)):
        row = int(np.argwhere(~np.isfinite(boxes))[0, 0])
        raise InvalidActionError(f"track {ids[row]} has a non-finite box {boxes[row].tolist()}")
    negative = (boxes[:, 2] < 0) | (boxes[:, 3] < 0)
    if negative.any():
        row = int(np.argmax(negative))
        raise InvalidActionError(f"track {ids[row]} has a negative size {boxes[row].tolist()}")
    outside = np.abs(boxes) > COORD_MAX
    if outside.any():
        row = int(np.argwhere(outside)[0, 0])
        raise InvalidActionError(
            f"track {ids[row]} has a box {boxes[row].tolist()} outside the action space: box "
            f"values must lie in [-{COORD_MAX:g}, {COORD_MAX:g}] pixels")
    if k != len(np.unique(ids)):
        values, counts = np.unique(ids, return_counts=True)
        raise InvalidActionError(f"duplicate track ids in one frame: {values[counts > 1].tolist()}")
    return ids, boxes


# ----------------------------------------------------------------- masks (MOTS, VIS)
class MaskStack(spaces.Space[np.ndarray]):
    """A ``bool`` stack of ``n`` binary masks of shape ``(n, H, W)``, ``n`` and size variable.

    Why a stack and not a label map: video instance segmentation detections may overlap (a
    label map cannot hold two masks on one pixel), and one representation for every mask task
    keeps agents simple (``masks[i]`` is detection ``i``). Why not padding to
    ``(max_detections, H, W)``: at 1080p that is 2 MB per padded slot per frame. The count
    is bounded by ``max_count`` and the size by ``max_height`` x ``max_width``; the masks have
    the frame's size, which varies between sequences (as :class:`Image` does).

    Args:
        max_count: largest number of masks.
        max_height: largest mask height.
        max_width: largest mask width.
        seed: seed of the space's random generator (used by :meth:`sample`).
    """

    def __init__(
        self, max_count: int, max_height: int, max_width: int, seed: int | None = None
    ) -> None:
        if max_count < 0 or max_height < 1 or max_width < 1:
            raise ValueError("MaskStack bounds must be positive (max_count >= 0)")
        self.max_count = int(max_count)
        self.max_height = int(max_height)
        self.max_width = int(max_width)
        super().__init__(shape=None, dtype=np.bool_, seed=seed)

    @property
    def is_np_flattenable(self) -> bool:
        """Stacks of varying size cannot be flattened to one fixed vector."""
        return False

    def sample(self, mask: Any = None, probability: Any = None) -> np.ndarray:
        """Return random masks: a random count (at most 3) of a random size within the bounds."""
        if mask is not None or probability is not None:
            raise NotImplementedError("MaskStack.sample does not support masks")
        count = int(self.np_random.integers(0, min(self.max_count, 3) + 1))
        height = int(self.np_random.integers(1, min(self.max_height, 32) + 1))
        width = int(self.np_random.integers(1, min(self.max_width, 32) + 1))
        return self.np_random.integers(0, 2, (count, height, width)).astype(bool)

    def contains(self, x: Any) -> bool:
        """Whether ``x`` is a ``bool`` array ``(n, H, W)`` within the bounds."""
        return (
            isinstance(x, np.ndarray)
            and x.dtype == np.bool_
            and x.ndim == 3
            and 0 <= x.shape[0] <= self.max_count
            and 1 <= x.shape[1] <= self.max_height
            and 1 <= x.shape[2] <= self.max_width
        )

    def __repr__(self) -> str:
        return (f"MaskStack(max_count={self.max_count}, max_height={self.max_height}, "
                f"max_width={self.max_width})")

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, MaskStack)
            and other.max_count == self.max_count
            and other.max_height == self.max_height
            and other.max_width == self.max_width
        )

    def to_jsonable(self, sample_n: Sequence[np.ndarray]) -> list:
        """Convert a batch of mask stacks to lists."""
        return [masks.tolist() for masks in sample_n]

    def from_jsonable(self, sample_n: Sequence[Any]) -> list[np.ndarray]:
        """Convert lists back to mask stacks."""
        return [np.asarray(masks, dtype=bool) for masks in sample_n]


def mask_boxes(masks: np.ndarray) -> np.ndarray:
    """Return the tight ``(x, y, w, h)`` box of each mask of an ``(n, H, W)`` stack.

    Coordinates are 0-based pixels (``x`` = first column with a pixel, ``w`` = columns
    spanned), as ``pycocotools.mask.toBbox`` computes them; empty masks get ``(0, 0, 0, 0)``.

    >>> m = np.zeros((1, 4, 5), bool); m[0, 1:3, 2:5] = True
    >>> mask_boxes(m).tolist()
    [[2.0, 1.0, 3.0, 2.0]]
    """
    masks = np.asarray(masks, dtype=bool)
    out = np.zeros((len(masks), 4), dtype=np.float64)
    for i, mask in enumerate(masks):
        rows = np.flatnonzero(mask.any(axis=1))
        if not rows.size:
            continue
        cols = np.flatnonzero(mask.any(axis=0))
        out[i] = (cols[0], rows[0], cols[-1] - cols[0] + 1, rows[-1] - rows[0] + 1)
    return out


def mask_observation_space(
    max_detections: int, max_frame_size: tuple[int, int], *, num_classes: int | None = None
) -> spaces.Dict:
    """Observation space of mask association tasks (MOTS, VIS).

    Keys: ``frame`` (:class:`Image`), ``masks`` (:class:`MaskStack`, ``num_detections``
    masks of the frame's size), ``boxes`` / ``scores`` padded as in
    :func:`detection_observation_space`, ``num_detections``, and with ``num_classes`` a
    padded ``classes`` ``(max_detections,) int64`` in ``[0, num_classes]`` (0 = padding).
    """
    entries: dict[str, spaces.Space] = {
        "frame": Image(*max_frame_size),
        "masks": MaskStack(max_detections, *max_frame_size),
        "boxes": box_array_space(max_detections),
        "scores": spaces.Box(-FLOAT_MAX, FLOAT_MAX, (max_detections,), np.float32),
        "num_detections": spaces.Discrete(max_detections + 1),
    }
    if num_classes is not None:
        entries["classes"] = spaces.Box(0, int(num_classes), (max_detections,), np.int64)
    return spaces.Dict(entries)


def mask_id_action_space(max_detections: int) -> spaces.Dict:
    """Action space of mask association tasks: one track id per observed detection.

    ``ids[i]`` is the track id given to detection ``i`` (``i < num_detections``); 0 means
    "not reported". Entries at ``i >= num_detections`` are ignored.
    """
    return spaces.Dict(
        {"ids": spaces.Box(0, np.iinfo(np.int32).max, (max_detections,), np.int64)}
    )


def pack_mask_ids(ids: Any, max_detections: int) -> dict[str, Any]:
    """Build a padded mask-id action from one id per detection (0 = not reported).

    >>> pack_mask_ids([4, 0, 9], max_detections=5)["ids"].tolist()
    [4, 0, 9, 0, 0]
    """
    arr = np.asarray(ids, dtype=np.int64).reshape(-1)
    if len(arr) > max_detections:
        raise InvalidActionError(f"{len(arr)} ids exceed max_detections={max_detections}")
    out = np.zeros(max_detections, dtype=np.int64)
    out[: len(arr)] = arr
    return {"ids": out}


def unpack_mask_ids(
    action: Any, num_detections: int, max_detections: int | None = None
) -> np.ndarray:
    """Validate a mask-id action and return the ``(num_detections,)`` int64 ids.

    Accepts ``{"ids": (max_detections,)}`` (padded; entries past ``num_detections`` are
    ignored) or ``{"ids": (num_detections,)}``.

    Raises:
        InvalidActionError: not a dict with ``ids``; wrong length or dtype; negative ids;
            a non-zero id given to two detections of the frame.
    """
    if not isinstance(action, dict) or "ids" not in action:
        raise InvalidActionError(
            "action must be a dict {'ids': one track id per detection (0 = not reported)}; "
            "build one with unitrack_env.spaces.pack_mask_ids(ids, max_detections)"
        )
    ids = np.asarray(action["ids"])
    if ids.ndim != 1:
        raise InvalidActionError(f"action['ids'] must be 1-D, got shape {ids.shape}")
    if len(ids) not in (num_detections, max_detections):
        expected = f"{num_detections}" + (
            f" (or {max_detections} padded)" if max_detections is not None else "")
        raise InvalidActionError(
            f"action['ids'] has {len(ids)} entries; this frame has {expected} detections")
    ids = _checked_ids(ids, num_detections, low=0)
    reported = ids[ids > 0]
    if len(reported) != len(np.unique(reported)):
        values, counts = np.unique(reported, return_counts=True)
        raise InvalidActionError(
            f"one track id given to several detections of a frame: {values[counts > 1].tolist()}")
    return ids


class LabelMap(spaces.Space[np.ndarray]):
    """A ``uint8`` label map of shape ``(H, W)`` whose size may vary between episodes.

    The 2-D counterpart of :class:`Image` for segmentation masks whose pixel values are
    labels (0 = background, ``k`` = object ``k``; DAVIS adds 255 = void).

    Sampling: a label map of size ``(H, W)`` is only a valid action for a frame of that
    size, so an environment calls :meth:`narrow` at every reset with the current frame
    size and the labels allowed in this episode; :meth:`sample` then draws valid actions.
    Before any :meth:`narrow`, it draws a small map of random size. :meth:`contains` and
    equality depend only on the bounds.

    Args:
        max_height: largest accepted height.
        max_width: largest accepted width.
        max_label: largest accepted label (at most 255).
        seed: seed of the space's own random generator (used by :meth:`sample`).
    """

    def __init__(
        self, max_height: int, max_width: int, max_label: int = 255, seed: int | None = None
    ) -> None:
        if max_height < 1 or max_width < 1:
            raise ValueError("LabelMap space bounds must be positive")
        if not 0 <= max_label <= 255:
            raise ValueError(f"max_label must lie in 0..255 (uint8); got {max_label}")
        self.max_height = int(max_height)
        self.max_width = int(max_width)
        self.max_label = int(max_label)
        self._sample_shape: tuple[int, int] | None = None
        self._sample_labels: np.ndarray | None = None
        super().__init__(shape=None, dtype=np.uint8, seed=seed)

    @property
    def is_np_flattenable(self) -> bool:
        """Maps of varying size cannot be flattened to one fixed vector."""
        return False

    def narrow(self, height: int, width: int, labels: Sequence[int]) -> None:
        """Make :meth:`sample` draw ``(height, width)`` maps with values from ``labels``."""
        values = np.asarray(sorted({int(v) for v in labels}), dtype=np.uint8)
        if len(values) == 0 or int(values.max()) > self.max_label:
            raise ValueError(f"labels must be a non-empty subset of 0..{self.max_label}")
        if not (1 <= height <= self.max_height and 1 <= width <= self.max_width):
            raise ValueError(f"size {height}x{width} exceeds the space's bounds")
        self._sample_shape = (int(height), int(width))
        self._sample_labels = values

    def sample(self, mask: Any = None, probability: Any = None) -> np.ndarray:
        """Return a random label map (of the narrowed size and labels, see the class doc)."""
        if mask is not None or probability is not None:
            raise NotImplementedError("LabelMap.sample does not support masks")
        if self._sample_shape is None or self._sample_labels is None:
            height = int(self.np_random.integers(1, min(self.max_height, 64) + 1))
            width = int(self.np_random.integers(1, min(self.max_width, 64) + 1))
            return self.np_random.integers(0, self.max_label + 1, (height, width), dtype=np.uint8)
        index = self.np_random.integers(0, len(self._sample_labels), self._sample_shape)
        return self._sample_labels[index]

    def contains(self, x: Any) -> bool:
        """Whether ``x`` is a 2-D ``uint8`` map within the size and label bounds."""
        return (
            isinstance(x, np.ndarray)
            and x.dtype == np.uint8
            and x.ndim == 2
            and 1 <= x.shape[0] <= self.max_height
            and 1 <= x.shape[1] <= self.max_width
            and (x.size == 0 or int(x.max()) <= self.max_label)
        )

    def __repr__(self) -> str:
        return (f"LabelMap(max_height={self.max_height}, max_width={self.max_width}, "
                f"max_label={self.max_label})")

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, LabelMap)
            and other.max_height == self.max_height
            and other.max_width == self.max_width
            and other.max_label == self.max_label
        )

    def to_jsonable(self, sample_n: Sequence[np.ndarray]) -> list:
        """Convert a batch of label maps to lists."""
        return [labels.tolist() for labels in sample_n]

    def from_jsonable(self, sample_n: Sequence[Any]) -> list[np.ndarray]:
        """Convert lists back to label maps."""
        return [np.asarray(labels, dtype=np.uint8) for labels in sample_n]


# --------------------------------------------------------------------------- keypoints
def keypoint_array_space(capacity: int, num_keypoints: int) -> spaces.Box:
    """``(capacity, num_keypoints, 3)`` float32 ``(x, y, score)`` poses; padding is 0.

    ``x, y`` are finite pixels (``|v| <= COORD_MAX``); ``score`` lies in ``[0, 1]``, where 0
    marks an absent keypoint.
    """
    low = np.tile(np.array([-COORD_MAX, -COORD_MAX, 0.0], np.float32), (capacity, num_keypoints, 1))
    high = np.tile(np.array([COORD_MAX, COORD_MAX, 1.0], np.float32), (capacity, num_keypoints, 1))
    return spaces.Box(low, high, (capacity, num_keypoints, 3), np.float32)


def pose_track_action_space(max_tracks: int, num_keypoints: int) -> spaces.Dict:
    """Action space of pose association tasks: padded ``ids``/``keypoints`` and ``num_tracks``."""
    return spaces.Dict(
        {
            # ids >= 1; 0 marks the padding past num_tracks
            "ids": spaces.Box(0, np.iinfo(np.int32).max, (max_tracks,), np.int64),
            "keypoints": keypoint_array_space(max_tracks, num_keypoints),
            "num_tracks": spaces.Discrete(max_tracks + 1),
        }
    )


def pack_pose_tracks(ids: Any, keypoints: Any, max_tracks: int) -> dict[str, Any]:
    """Build a padded pose-track action from ``k`` ids and ``(k, K, 3)`` keypoints.

    >>> action = pack_pose_tracks([4], np.ones((1, 17, 3)), max_tracks=3)
    >>> action["num_tracks"], action["ids"].tolist(), action["keypoints"].shape
    (1, [4, 0, 0], (3, 17, 3))
    """
    ids_arr = np.asarray(ids, dtype=np.int64).reshape(-1)
    kp = np.asarray(keypoints, dtype=np.float32)
    k = len(ids_arr)
    if kp.ndim != 3 or kp.shape[0] != k or kp.shape[2] != 3:
        raise InvalidActionError(f"{k} ids need keypoints of shape ({k}, K, 3); got {kp.shape}")
    if k > max_tracks:
        raise InvalidActionError(
            f"{k} tracks exceed the action capacity max_tracks={max_tracks}; "
            "raise max_tracks when making the environment"
        )
    out_ids = np.zeros(max_tracks, dtype=np.int64)
    out_kp = np.zeros((max_tracks,) + kp.shape[1:], dtype=np.float32)
    out_ids[:k] = ids_arr
    out_kp[:k] = kp
    return {"ids": out_ids, "keypoints": out_kp, "num_tracks": k}


def unpack_poses(observation: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Return the valid ``(keypoints (n, K, 3), scores (n,))`` of a pose observation."""
    n = int(observation["num_people"])
    return observation["keypoints"][:n], observation["scores"][:n]


def unpack_pose_tracks(
    action: dict[str, Any], max_tracks: int | None = None, num_keypoints: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Validate a pose-track action and return ``(ids (k,) int64, keypoints (k, K, 3) float64)``.

    Accepts the padded form (with ``num_tracks``) or the unpadded ``{"ids", "keypoints"}``.

    Raises:
        InvalidActionError: wrong keys, shapes or dtypes; NaN/inf coordinates; scores
            outside ``[0, 1]``; ids that are not positive integers or repeat.
    """
    if not isinstance(action, dict) or "ids" not in action or "keypoints" not in action:
        raise InvalidActionError(
            "action must be a dict with 'ids' and 'keypoints' (and optionally 'num_tracks'); "
            "build one with unitrack_env.spaces.pack_pose_tracks(ids, keypoints, max_tracks)"
        )
    ids = np.asarray(action["ids"])
    kp = np.asarray(action["keypoints"])
    if ids.ndim != 1:
        raise InvalidActionError(f"action['ids'] must be 1-D, got shape {ids.shape}")
    if kp.ndim != 3 or kp.shape[2] != 3 or (num_keypoints is not None
                                             and kp.shape[1] != num_keypoints):
        want = f"(k, {num_keypoints if num_keypoints is not None else 'K'}, 3)"
        raise InvalidActionError(f"action['keypoints'] must have shape {want}, got {kp.shape}")
    if not (np.issubdtype(kp.dtype, np.floating) or np.issubdtype(kp.dtype, np.integer)):
        raise InvalidActionError(f"action['keypoints'] must be numbers, got dtype {kp.dtype}")
    if "num_tracks" in action:
        k = _action_count(action, "num_tracks")
        if not 0 <= k <= min(len(ids), len(kp)):
            raise InvalidActionError(
                f"num_tracks={k} but the arrays hold {len(ids)} ids and {len(kp)} poses")
    else:
        k = len(ids)
        if len(kp) != k:
            raise InvalidActionError(f"{k} ids but {len(kp)} poses")
    if max_tracks is not None and k > max_tracks:
        raise InvalidActionError(f"{k} tracks exceed max_tracks={max_tracks}")
    ids = _checked_ids(ids, k)
    kp = kp[:k].astype(np.float64)
    if not np.all(np.isfinite(kp)):
        row = int(np.argwhere(~np.isfinite(kp))[0, 0])
        raise InvalidActionError(f"track {ids[row]} has non-finite keypoints")
    if k and (kp[..., 2].min() < 0 or kp[..., 2].max() > 1):
        raise InvalidActionError("keypoint scores (the third value) must lie in [0, 1]")
    if k and np.abs(kp[..., :2]).max() > COORD_MAX:
        row = int(np.argwhere(np.abs(kp[..., :2]) > COORD_MAX)[0, 0])
        raise InvalidActionError(
            f"track {ids[row]} has a keypoint outside the action space: x and y must lie in "
            f"[-{COORD_MAX:g}, {COORD_MAX:g}] pixels")
    if k != len(np.unique(ids)):
        values, counts = np.unique(ids, return_counts=True)
        raise InvalidActionError(f"duplicate track ids in one frame: {values[counts > 1].tolist()}")
    return ids, kp
