"""Bounds of the action and observation spaces, and the checks every action shares.

Ids, counts and coordinates are checked the same way for boxes, masks and poses; each task
family's module (:mod:`.boxes`, :mod:`.masks`, :mod:`.poses`) builds on these.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unitrack_env.errors import InvalidActionError

#: infinities and make ``check_env`` warn).
FLOAT_MAX = float(np.finfo(np.float32).max)
#: Bound of box coordinates in pixels (generous: boxes may extend past the frame).
COORD_MAX = 1e5
#: Largest track id of the action spaces. Official result files store ids as numbers that
#: are read back as floats (MOTChallenge txt) or JSON numbers; int32 ids survive every one
#: of them exactly (float64 holds integers only up to 2**53).
ID_MAX = int(np.iinfo(np.int32).max)


def action_count(action: dict[str, Any], key: str) -> int:
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


def checked_ids(ids: np.ndarray, k: int, *, low: int = 1) -> np.ndarray:
    """The first ``k`` ids as int64 after checking integer values in ``low..ID_MAX``."""
    ids = ids[:k]
    if ids.dtype == object and ids.size and all(
            isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in ids.flat):
        # Python ints beyond int64 (e.g. 2**70) make numpy fall back to an object array
        huge = [int(v) for v in ids.flat if not -2**63 <= int(v) < 2**63]
        if huge:
            raise InvalidActionError(
                f"track id {huge[0]} is out of range {low}..{ID_MAX}, the ids of the action "
                "space (ids must survive the official result files, which store them as "
                "floats)")
        ids = ids.astype(np.int64)
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



def track_count(
    action: dict[str, Any], num_ids: int, num_values: int, noun: str, max_tracks: int | None
) -> int:
    """The number ``k`` of tracks a padded or unpadded track action reports.

    ``num_ids`` and ``num_values`` are the lengths of the action's ``ids`` and of its
    per-track values (``noun``: ``"boxes"`` or ``"poses"``); ``num_tracks``, when given,
    must fit both, and ``k`` must fit ``max_tracks``.
    """
    if "num_tracks" in action:
        k = action_count(action, "num_tracks")
        if not 0 <= k <= min(num_ids, num_values):
            raise InvalidActionError(
                f"num_tracks={k} but the arrays hold {num_ids} ids and {num_values} {noun}"
            )
    else:
        k = num_ids
        if num_values != k:
            raise InvalidActionError(f"{k} ids but {num_values} {noun}")
    if max_tracks is not None and k > max_tracks:
        raise InvalidActionError(f"{k} tracks exceed max_tracks={max_tracks}")
    return k


def refuse_duplicate_ids(ids: np.ndarray) -> None:
    """Raise when a track id appears twice in one frame's action."""
    if len(ids) != len(np.unique(ids)):
        values, counts = np.unique(ids, return_counts=True)
        raise InvalidActionError(f"duplicate track ids in one frame: {values[counts > 1].tolist()}")


def check_capacity(k: int, max_tracks: int) -> None:
    """Raise when ``k`` tracks do not fit the action capacity ``max_tracks``."""
    if k > max_tracks:
        raise InvalidActionError(
            f"{k} tracks exceed the action capacity max_tracks={max_tracks}; "
            "raise max_tracks when making the environment"
        )


def pad_tracks(ids: np.ndarray, values: np.ndarray, key: str, max_tracks: int) -> dict[str, Any]:
    """A padded track action: ``ids`` and per-track ``values`` (float32) under ``key``.

    ``ids`` and ``values`` hold ``k`` tracks (already checked to agree); both are padded
    with zeros to ``max_tracks`` rows, and ``num_tracks`` is ``k``.
    """
    k = len(ids)
    check_capacity(k, max_tracks)
    out_ids = np.zeros(max_tracks, dtype=np.int64)
    out_values = np.zeros((max_tracks,) + values.shape[1:], dtype=np.float32)
    out_ids[:k] = ids
    out_values[:k] = values
    return {"ids": out_ids, key: out_values, "num_tracks": k}


def track_arrays(action: Any, key: str, builder: str) -> tuple[np.ndarray, np.ndarray]:
    """The ``ids`` (checked 1-D) and the ``key`` values of a track action dict.

    ``builder`` names the helper that makes a valid action, for the error message.
    """
    if not isinstance(action, dict) or "ids" not in action or key not in action:
        raise InvalidActionError(
            f"action must be a dict with 'ids' and '{key}' (and optionally 'num_tracks'); "
            f"build one with unitrack_env.spaces.{builder}"
        )
    ids = np.asarray(action["ids"])
    values = np.asarray(action[key])
    if ids.ndim != 1:
        raise InvalidActionError(f"action['ids'] must be 1-D, got shape {ids.shape}")
    return ids, values


def require_numbers(values: np.ndarray, key: str) -> None:
    """Raise unless ``values`` (the action's ``key``) holds integers or floats."""
    if not (np.issubdtype(values.dtype, np.floating) or np.issubdtype(values.dtype, np.integer)):
        raise InvalidActionError(f"action['{key}'] must be numbers, got dtype {values.dtype}")


def valid_rows(
    observation: dict[str, Any], count_key: str, keys: tuple[str, ...]
) -> tuple[np.ndarray, ...]:
    """The first ``observation[count_key]`` rows of each padded array ``keys``."""
    n = int(observation[count_key])
    return tuple(observation[key][:n] for key in keys)


def checked_track_values(
    action: dict[str, Any], ids: np.ndarray, values: np.ndarray, key: str, noun: str,
    max_tracks: int | None,
) -> tuple[np.ndarray, np.ndarray]:
    """The reported tracks' checked ids (int64) and their ``key`` values (float64)."""
    require_numbers(values, key)
    k = track_count(action, len(ids), len(values), noun, max_tracks)
    return checked_ids(ids, k), values[:k].astype(np.float64)
