"""The UniTrack association head (agent ``unitrack``): boxes, masks and poses with one agent.

One agent plays MOT (boxes), MOTS (masks), VIS (masks with classes) and PoseTrack (poses):
at reset it reads the task, capacities and declared score range from the info and picks
the task's observation adapter and settings. Per frame (paper section 2.4, appendix C):
drop unusable observations; give each a Kalman box (a mask's mean/MAD box, a pose drawn
as a mask first); run the appearance model once on the letterboxed frame; pool object
features (a 10 x 4 RoIAlign grid per box, capped in-mask cells per mask); associate with
:class:`~unitrack_env.agents.primitives.association.Associator` (per class on VIS); act in
the environment's format. Options: :class:`UniTrackConfig`; why each default:
``docs/design-decisions.md``.

Example:
    >>> import gymnasium as gym, unitrack_env                    # doctest: +SKIP
    >>> from unitrack_env.agents import make_agent                             # doctest: +SKIP
    >>> env = gym.make("UniTrack/MOTS-v0")                        # doctest: +SKIP
    >>> agent = make_agent("unitrack")                            # doctest: +SKIP
    >>> obs, info = env.reset(); agent.reset(obs, info)           # doctest: +SKIP
    >>> obs, reward, terminated, truncated, info = env.step(agent.act(obs))  # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from unitrack_env.score_range import ScoreRange

from ..appearance.cached_model import CachedAppearanceModel
from ..appearance.feature_cache import resolve_cache
from ..appearance.letterboxing import Letterbox
from ..appearance.model import AppearanceModel, torch_threads
from ..base import Agent
from ..primitives.adapters import (
    Detections,
    ObservationAdapter,
    adapter_for,
    detect_task,
    reset_task,
)
from ..primitives.association import Associator
from ..primitives.association_config import AssociationConfig
from ..primitives.category_gating import CategoryGatedAssociator
from ..primitives.mask_features import LocalMask, mask_to_box, pose_to_mask
from ..primitives.similarity import SIMILARITIES, ObjectFeatures
from ..primitives.tracks import TrackOutput
from .region_features import RegionFeatures
from .unitrack_config import TASKS, UniTrackConfig

__all__ = ["UniTrackAgent"]


@dataclass(frozen=True)
class _Parsed:
    """One frame's usable observations: their indices, Kalman boxes, scores, masks, classes."""

    index: np.ndarray
    boxes: np.ndarray
    scores: np.ndarray
    masks: list[LocalMask] | None = None
    categories: np.ndarray | None = None


class UniTrackAgent(Agent, name="unitrack", tasks=TASKS):
    """UniTrack's association head for boxes, masks and poses (MOT, MOTS, VIS, PoseTrack).

    ``options`` are :class:`UniTrackConfig` fields; ``max_tracks`` (None: the reset info's
    ``capacities``) sizes box and pose actions; a shared ``appearance_model`` overrides the
    appearance options. ``settings`` is the config resolved on the task being played; the
    episode state lives in ``associator``.
    """

    config_class = UniTrackConfig

    def __init__(
        self,
        max_tracks: int | None = None,
        *,
        appearance_model: AppearanceModel | None = None,
        **options: Any,
    ) -> None:
        self.config = UniTrackConfig.from_options(self.name, options)
        cfg = self.config
        #: The config resolved on each task it may play, once (:meth:`UniTrackConfig.resolve`).
        self.configs = {task: cfg.resolve(task) for task in ((cfg.task,) if cfg.task else TASKS)}
        self._engines: dict[tuple[str, ScoreRange | None], AssociationConfig] = {}
        self._max_tracks = None if max_tracks is None else int(max_tracks)
        if callable(cfg.similarity):
            self._similarity: Callable[..., Any] = cfg.similarity
        else:
            self._similarity = SIMILARITIES[cfg.similarity]
        base = appearance_model or cfg.build()
        self.appearance = base
        # (an injected model without an identity cannot be keyed: it runs uncached)
        cache = resolve_cache(cfg.feature_cache, max_size=cfg.feature_cache_size) \
            if hasattr(base, "identity") else None
        self.model: AppearanceModel | CachedAppearanceModel = (
            CachedAppearanceModel(base, cache) if cache is not None else base
        )
        self.features = RegionFeatures(
            self.model, base.stride, input_size=cfg.input_size, roi_size=cfg.roi_size,
            sampling_ratio=cfg.roi_sampling_ratio, pixel_origin=cfg.pixel_origin)
        self._task_from_info = False
        #: The environment's declared score range (``info["detection_scores"]``), if any.
        self.score_range: ScoreRange | None = None
        self._start(cfg.task or "mot", {}, 30.0)

    @property
    def task(self) -> str:
        """The task being played."""
        return self.settings.task

    @property
    def max_tracks(self) -> int:
        """Action capacity of box and pose tracks on the current task."""
        return self.adapter.max_tracks

    def _start(self, task: str, capacities: Mapping[str, int], frame_rate: float) -> None:
        """Take ``task``'s resolved config and adapter; build its association engine."""
        if task not in self.configs:
            raise ValueError(f"unknown task {task!r}; valid tasks: {', '.join(self.configs)}")
        self.settings: UniTrackConfig = self.configs[task]
        key = (task, self.score_range)
        if key not in self._engines:
            self._engines[key] = self.settings.association(self.score_range)
        if self._max_tracks is not None:
            capacities = {**capacities, "max_tracks": self._max_tracks}
        self.adapter: ObservationAdapter = adapter_for(task, capacities)
        engine = CategoryGatedAssociator if self.settings.category_gating else Associator
        self.associator: Associator[Any] | CategoryGatedAssociator[Any] = engine(
            self._similarity, self._engines[key], frame_rate)

    # ------------------------------------------------------------------ episode
    def reset(self, observation: Any, info: dict[str, Any]) -> None:
        """Forget all tracks and ids; read the task, capacities, ``frame_rate`` and score range."""
        task = self.config.task or reset_task(observation, info, self.task)
        self.score_range = ScoreRange.from_info(info.get("detection_scores"))
        self._task_from_info = bool(info.get("task"))
        self._start(task, dict(info.get("capacities") or {}), self.associator.frame_rate)
        frame_rate = info.get("frame_rate")
        self.associator.reset(frame_rate=float(frame_rate) if frame_rate else None)
        if isinstance(self.model, CachedAppearanceModel):
            self.model.flush_stats()  # the previous episodes' hit counts, for `unitrack cache`

    def close(self) -> None:
        """Record the feature cache's hit counts (read by ``unitrack cache info``)."""
        if isinstance(self.model, CachedAppearanceModel):
            self.model.flush_stats()

    def act(self, observation: dict[str, Any]) -> dict[str, Any]:
        """Track one frame; return the action in the environment's format."""
        with torch_threads(self.config.num_threads):
            self._check_format(observation)
            detections = self.adapter.detections(observation)
            kind = self.adapter.kind
            if kind == "boxes":
                return self._act_boxes(observation["frame"], detections)
            if kind == "poses":
                return self._act_poses(observation["frame"], detections)
            return self._act_masks(observation["frame"], detections)

    def _check_format(self, observation: Mapping[str, Any]) -> None:
        """Refuse an observation of another task mid-episode (switch before the first one).

        A task fixed by the ``task`` option is not checked.
        """
        if self.config.task is not None:
            return
        task = detect_task(observation)
        if task == self.task:
            return
        engine = self.associator
        started = engine.frame_index > 0 if isinstance(engine, Associator) \
            else bool(engine.categories)
        if started or self._task_from_info:
            raise ValueError(
                f"the observation format changed from {self.task} to {task} in the middle "
                "of an episode; call reset() with the new environment's first observation"
            )
        self._start(task, {}, engine.frame_rate)

    def _step(self, parsed: _Parsed, features: Sequence[Any]) -> list[TrackOutput]:
        if isinstance(self.associator, CategoryGatedAssociator):
            categories = parsed.categories if parsed.categories is not None \
                else np.zeros(len(parsed.boxes), dtype=np.int64)
            return self.associator.step(parsed.boxes, parsed.scores, features, categories)
        return self.associator.step(parsed.boxes, parsed.scores, features)

    @staticmethod
    def _usable(scores: np.ndarray) -> np.ndarray:
        """Finite scores (which detections to keep is the environment's ``min_score``)."""
        return np.isfinite(scores)

    # ------------------------------------------------------------------ boxes (MOT)
    def _act_boxes(self, frame: np.ndarray, detections: Detections) -> dict[str, Any]:
        boxes = np.asarray(detections.boxes, dtype=np.float64)
        scores = np.asarray(detections.scores, dtype=np.float64)
        keep = np.all(np.isfinite(boxes), axis=1) & (boxes[:, 2] > 0) & (boxes[:, 3] > 0)
        keep &= self._usable(scores)
        parsed = _Parsed(np.flatnonzero(keep), boxes[keep], scores[keep])
        payloads = self.box_features(frame, parsed.boxes) if len(parsed.boxes) else []
        outputs = self._step(parsed, payloads)
        return self.adapter.action(
            detections, [o.track_id for o in outputs],
            parsed.index[[o.detection_index for o in outputs]],
            np.array([o.box for o in outputs]).reshape(-1, 4),
        )

    # ------------------------------------------------------------------ masks (MOTS, VIS)
    def _act_masks(self, frame: np.ndarray, detections: Detections) -> dict[str, Any]:
        scores = np.asarray(detections.scores, dtype=np.float64)
        masks = [LocalMask.from_full(m) for m in np.asarray(detections.masks)]
        keep = np.array([m.area > 0 for m in masks], dtype=bool).reshape(-1)
        keep &= self._usable(scores)
        parsed = self._parse_masks(np.flatnonzero(keep), masks, scores, detections.classes)
        outputs = self._step(parsed, self._region_features(frame, parsed))
        return self.adapter.action(detections, [o.track_id for o in outputs],
                                   parsed.index[[o.detection_index for o in outputs]])

    def _parse_masks(self, index: np.ndarray, masks: Sequence[LocalMask], scores: np.ndarray,
                     classes: np.ndarray | None) -> _Parsed:
        kept = [masks[i] for i in index]
        if self.settings.mask_box == "mad":
            boxes = [mask_to_box(m) for m in kept]
        else:
            boxes = [m.tight_box() for m in kept]
        categories = None
        if classes is not None and self.settings.category_gating:
            categories = np.asarray(classes, dtype=np.int64)[index]
        return _Parsed(index, np.array(boxes, dtype=np.float64).reshape(-1, 4), scores[index],
                       kept, categories)

    # ------------------------------------------------------------------ poses (PoseTrack)
    def _act_poses(self, frame: np.ndarray, detections: Detections) -> dict[str, Any]:
        keypoints = np.asarray(detections.keypoints, dtype=np.float64)
        scores = np.asarray(detections.scores, dtype=np.float64)
        masks: list[LocalMask] = []
        keep = self._usable(scores) & np.all(np.isfinite(keypoints), axis=(1, 2))
        for i in range(len(keypoints)):
            mask = pose_to_mask(keypoints[i], min_score=self.settings.min_keypoint_score) \
                if keep[i] else None
            masks.append(mask if mask is not None else LocalMask(np.zeros((0, 0), bool)))
            keep[i] = mask is not None
        parsed = self._parse_masks(np.flatnonzero(keep), masks, scores, None)
        outputs = self._step(parsed, self._region_features(frame, parsed))
        rows = np.array([parsed.index[o.detection_index] for o in outputs], dtype=np.int64)
        return self.adapter.action(detections, [o.track_id for o in outputs], rows)

    # ------------------------------------------------------------------ features
    def feature_map(self, frame: np.ndarray) -> tuple[torch.Tensor, Letterbox]:
        """Letterbox ``frame``; its ``(1, C, h, w)`` feature map and the letterbox."""
        return self.features.feature_map(frame)

    def box_features(self, frame: np.ndarray, boxes_xywh: np.ndarray) -> list[torch.Tensor]:
        """L2-normalised location features ``(rows * cols, C)`` of each box of one frame."""
        return self.features.boxes(frame, boxes_xywh)

    def mask_features(self, frame: np.ndarray,
                      masks: Sequence[LocalMask]) -> list[ObjectFeatures]:
        """In-mask location features of each non-empty mask (the task's ``max_mask_area``)."""
        return self.features.masks(frame, masks, self.settings.max_mask_area)

    def _region_features(self, frame: np.ndarray, parsed: _Parsed) -> list[ObjectFeatures]:
        if not parsed.masks:
            return []
        return self.mask_features(frame, parsed.masks)
