"""Observation adapters: the association environments' observations in, their actions out.

An association agent (``unitrack``, ``iou``) has one core and three observation formats:
:class:`BoxAdapter` (MOT), :class:`MaskAdapter` (MOTS, VIS; one id per detection, 0 = not
reported) and :class:`PoseAdapter` (PoseTrack). Adapters are sized by the reset info's
``capacities`` and pick the task from ``info["task"]``, else from the observation's keys.

Example:
    >>> import numpy as np
    >>> adapter = adapter_for("mot", {"max_tracks": 3})
    >>> obs = {"boxes": np.ones((4, 4), np.float32), "scores": np.ones(4, np.float32),
    ...        "num_detections": 2}
    >>> adapter.action(adapter.detections(obs), [7], [1], np.ones((1, 4)))["ids"].tolist()
    [7, 0, 0]
"""

from __future__ import annotations

import abc
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from unitrack_env.spaces.boxes import pack_tracks, unpack_detections
from unitrack_env.spaces.masks import pack_mask_ids
from unitrack_env.spaces.poses import pack_pose_tracks, unpack_poses


@dataclass(frozen=True)
class Detections:
    """One frame's detections as the observation gives them (its dtypes, no filtering).

    Row ``i`` is the observation's detection ``i``. ``boxes`` ``(n, 4)`` (empty for poses),
    ``scores``; ``masks``, ``keypoints``, ``classes`` are None unless the task has them;
    ``capacity`` is the padded length.
    """

    boxes: np.ndarray
    scores: np.ndarray
    masks: np.ndarray | None = None
    keypoints: np.ndarray | None = None
    classes: np.ndarray | None = None
    capacity: int = 0

    def __len__(self) -> int:
        return len(self.scores)


class ObservationAdapter(abc.ABC):
    """Reads one association format's observations and writes its actions.

    ``capacities`` are the environment's (``info["capacities"]``); missing entries take the
    environments' defaults. ``kind`` is ``"boxes"``, ``"masks"`` or ``"poses"``.
    """

    kind: ClassVar[str] = ""

    def __init__(self, task: str, capacities: Mapping[str, int] | None = None) -> None:
        self.task = task
        self.capacities = dict(capacities or {})

    @property
    def max_tracks(self) -> int:
        """Action capacity of box and pose tracks (else: the environments' default)."""
        return int(self.capacities.get("max_tracks") or default_max_tracks(self.task))

    @abc.abstractmethod
    def detections(self, observation: Mapping[str, Any]) -> Detections:
        """The frame's ``num_detections`` (or ``num_people``) detections."""

    @abc.abstractmethod
    def action(self, detections: Detections, ids: Sequence[int], rows: Sequence[int],
               boxes: np.ndarray | None = None) -> dict[str, Any]:
        """The action reporting track ``ids[k]`` on detection ``rows[k]`` (its box ``boxes[k]``)."""


class BoxAdapter(ObservationAdapter):
    """MOT boxes: ``boxes``/``scores``/``num_detections`` in; ``ids``/``boxes`` out."""

    kind = "boxes"

    def detections(self, observation: Mapping[str, Any]) -> Detections:
        """The frame's detection boxes and scores."""
        boxes, scores = unpack_detections(observation)  # type: ignore[arg-type]
        return Detections(boxes, scores, capacity=len(observation["scores"]))

    def action(self, detections: Detections, ids: Sequence[int], rows: Sequence[int],
               boxes: np.ndarray | None = None) -> dict[str, Any]:
        """``ids`` with their ``boxes`` (required), padded to ``max_tracks``."""
        if boxes is None:
            raise ValueError("box actions need the reported boxes")
        return pack_tracks(ids, np.asarray(boxes).reshape(-1, 4), self.max_tracks)


class MaskAdapter(ObservationAdapter):
    """MOTS / VIS masks: ``masks``/``scores`` (``classes``) in; one id per detection out."""

    kind = "masks"

    def detections(self, observation: Mapping[str, Any]) -> Detections:
        """The frame's masks, scores, boxes and (VIS) classes."""
        n = int(observation["num_detections"])
        classes = observation.get("classes")
        return Detections(
            np.asarray(observation["boxes"][:n]), np.asarray(observation["scores"][:n]),
            masks=np.asarray(observation["masks"][:n]),
            classes=None if classes is None else np.asarray(classes[:n]),
            capacity=len(observation["scores"]),
        )

    def action(self, detections: Detections, ids: Sequence[int], rows: Sequence[int],
               boxes: np.ndarray | None = None) -> dict[str, Any]:
        """Detection ``rows[k]`` gets id ``ids[k]``; every other detection 0."""
        per_detection = np.zeros(len(detections), dtype=np.int64)
        per_detection[np.asarray(rows, dtype=np.int64)] = np.asarray(ids, dtype=np.int64)
        capacity = self.capacities.get("max_detections") or detections.capacity
        return pack_mask_ids(per_detection, int(capacity))


class PoseAdapter(ObservationAdapter):
    """PoseTrack poses: ``keypoints``/``scores``/``num_people`` in; ids and matched poses out."""

    kind = "poses"

    def detections(self, observation: Mapping[str, Any]) -> Detections:
        """The frame's poses and their scores."""
        keypoints, scores = unpack_poses(observation)  # type: ignore[arg-type]
        return Detections(np.zeros((0, 4)), np.asarray(scores), keypoints=np.asarray(keypoints),
                          capacity=len(observation["scores"]))

    def action(self, detections: Detections, ids: Sequence[int], rows: Sequence[int],
               boxes: np.ndarray | None = None) -> dict[str, Any]:
        """``ids`` with the observed poses of ``rows``, padded to ``max_tracks``."""
        assert detections.keypoints is not None
        poses = np.asarray(detections.keypoints, dtype=np.float32)[np.asarray(rows, np.int64)]
        return pack_pose_tracks(ids, poses, self.max_tracks)


ADAPTERS: Mapping[str, type[ObservationAdapter]] = MappingProxyType({
    "mot": BoxAdapter,
    "mots": MaskAdapter,
    "vis": MaskAdapter,
    "posetrack": PoseAdapter,
})
"""Association task -> its adapter class (read-only)."""


def adapter_for(task: str, capacities: Mapping[str, int] | None = None) -> ObservationAdapter:
    """The adapter of ``task`` sized by ``capacities``; ValueError lists the valid tasks."""
    try:
        return ADAPTERS[task](task, capacities)
    except KeyError:
        raise ValueError(
            f"unknown association task {task!r}; valid tasks: {', '.join(ADAPTERS)}") from None


def default_max_tracks(task: str) -> int:
    """The environments' default ``max_tracks`` of ``task``, read from the env modules."""
    if task == "posetrack":
        # lazy: start-up cost (unitrack_env.envs.posetrack)
        from unitrack_env.envs.posetrack import DEFAULT_MAX_TRACKS as POSE_TRACKS

        return int(POSE_TRACKS)
    # lazy: start-up cost (unitrack_env.envs.motchallenge)
    from unitrack_env.envs.motchallenge import DEFAULT_MAX_TRACKS as BOX_TRACKS

    return int(BOX_TRACKS)


def detect_task(observation: Mapping[str, Any]) -> str:
    """The association task of an observation from its keys (when no ``info["task"]`` is given).

    >>> detect_task({"frame": None, "masks": None, "classes": None})
    'vis'
    """
    if not isinstance(observation, Mapping):
        raise ValueError(f"expected a dict observation, got {type(observation).__name__}")
    if "keypoints" in observation:
        return "posetrack"
    if "masks" in observation:
        return "vis" if "classes" in observation else "mots"
    if "boxes" in observation:
        return "mot"
    raise ValueError(
        f"cannot tell the association task from the observation keys {sorted(observation)}; "
        "expected 'boxes' (MOT), 'masks' (MOTS; with 'classes': VIS) or 'keypoints' "
        "(PoseTrack), or pass task= to the agent"
    )


def reset_task(observation: Any, info: Mapping[str, Any], current: str) -> str:
    """The task of a new episode: ``info["task"]``, else the observation's, else ``current``."""
    task = info.get("task")
    if task:
        return str(task)
    if observation is None:
        return current
    return detect_task(observation)


def episode_adapter(observation: Any, info: Mapping[str, Any], current: str,
                    max_tracks: int | None = None) -> ObservationAdapter:
    """The adapter of a new episode: its task (:func:`reset_task`) sized by the reset info.

    ``current`` is kept when neither info nor observation tells the task; ``max_tracks``
    overrides ``info["capacities"]``.
    """
    capacities = dict(info.get("capacities") or {})
    if max_tracks is not None:
        capacities["max_tracks"] = int(max_tracks)
    return adapter_for(reset_task(observation, info, current), capacities)
