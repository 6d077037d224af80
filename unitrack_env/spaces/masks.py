"""Mask association spaces (MOTS, VIS): mask observations and one-id-per-detection actions."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from unitrack_env.errors import InvalidActionError
from unitrack_env.spaces.arrays import Image, MaskStack
from unitrack_env.spaces.boxes import box_array_space
from unitrack_env.spaces.limits import FLOAT_MAX, checked_ids


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

    ``frame``, ``masks`` (a :class:`MaskStack`), padded ``boxes``/``scores`` and
    ``num_detections``; with ``num_classes``, padded ``classes`` in ``[0, num_classes]``.
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
    """Validate a mask-id action (padded or ``(num_detections,)``) and return the int64 ids.

    InvalidActionError on a bad shape or dtype, negative ids, or one non-zero id given twice.
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
    ids = checked_ids(ids, num_detections, low=0)
    reported = ids[ids > 0]
    if len(reported) != len(np.unique(reported)):
        values, counts = np.unique(reported, return_counts=True)
        raise InvalidActionError(
            f"one track id given to several detections of a frame: {values[counts > 1].tolist()}")
    return ids

