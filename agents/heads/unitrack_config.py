"""Options of the ``unitrack`` association agent and what they resolve to per task.

:meth:`UniTrackConfig.settings` resolves the options, :data:`TASK_DEFAULTS` and the
:class:`AssociationConfig` preset into one :class:`TaskSettings` per task. Why each
default: ``docs/design-decisions.md``.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

from unitrack_env.score_range import ScoreRange

from ..appearance.letterboxing import MOT_INPUT_SIZE
from ..appearance.spec import AppearanceSpec
from ..primitives.association_config import (
    MOT_OUTPUT_MAX_ASPECT,
    MOT_OUTPUT_MIN_AREA,
    PRESETS,
    AssociationConfig,
)
from ..primitives.mask_features import MAX_MASK_AREA_MOTS, MAX_MASK_AREA_VIS

ROI_OUTPUT_SIZE: tuple[int, int] = (10, 4)
"""(rows, columns) of the RoIAlign grid per box: 40 location features (tall, for people)."""

MOT_PIXEL_ORIGIN: float = 1.0
"""MOTChallenge boxes are 1-based (the top-left pixel is (1, 1)); subtracting this maps them
to continuous 0-based image coordinates before pooling features."""

TASKS: tuple[str, ...] = ("mot", "mots", "vis", "posetrack")
"""Association tasks the agent plays."""

MASK_BOX_MODES: tuple[str, ...] = ("mad", "tight")
"""How a mask becomes a Kalman box: the paper's mean-absolute-deviation box, or the tight box."""

#: Association fields that are agent options: set them as options, not in ``association``.
AGENT_LEVEL_FIELDS = ("use_motion", "new_track_score", "output_min_area", "output_max_aspect")


@dataclass(frozen=True)
class TaskDefaults:
    """What a task is to the ``unitrack`` agent: observation kind, mask cap, class gating."""

    observation: str
    max_mask_area: int | None = None
    category_gating: bool = False


TASK_DEFAULTS: Mapping[str, TaskDefaults] = MappingProxyType({
    "mot": TaskDefaults("boxes"),
    "mots": TaskDefaults("masks", max_mask_area=MAX_MASK_AREA_MOTS),
    "vis": TaskDefaults("masks", max_mask_area=MAX_MASK_AREA_VIS, category_gating=True),
    # The authors give no mask-area cap for poses; PoseTrack people are MOTS-sized.
    "posetrack": TaskDefaults("poses", max_mask_area=MAX_MASK_AREA_MOTS),
})
"""Task name -> :class:`TaskDefaults` (read-only)."""


@dataclass(frozen=True)
class UniTrackConfig(AppearanceSpec):
    """Options of the ``unitrack`` agent (paper value in brackets).

    Appearance model (:class:`AppearanceSpec`): ``weights``, ``arch``, ``layer``, ``remap``,
    ``device``, ``runtime``, ``num_threads`` (torch threads while the agent acts).

    Attributes:
        task: ``"mot"``, ``"mots"``, ``"vis"``, ``"posetrack"``; None: the environment's.
        preset: ``"default"`` (the paper's setting with five measured departures on MOT,
            :meth:`AssociationConfig.mot`) or ``"paper"`` [paper] (:meth:`AssociationConfig.paper`).
        similarity: ``"rsm"`` [paper], ``"cf"``, ``"gf"``, ``"gpf"``, or a callable
            ``(tracks, detections) -> (N, M) similarity``.
        use_motion: Fuse Kalman motion into the appearance stage [True; False is the
            paper's "w/o motion" setting].
        new_track_score: Least score of a detection that starts a track, on 0..1 of the
            environment's declared score range (``info["detection_scores"]``) [0.5].
        input_size: ``(width, height)`` of the letterboxed network input [1088 x 608].
        roi_size: ``(rows, columns)`` of the RoIAlign grid of a box [(10, 4)].
        roi_sampling_ratio: Bilinear samples per RoIAlign bin and axis [2].
        feature_cache: The on-disk feature cache: True the user cache folder
            (``$UNITRACK_FEATURE_CACHE``), a folder, or False / None [none].
        feature_cache_size: Cap of the cache folder, e.g. ``"10GiB"`` (None: 10 GiB).
        output_filter: Report only boxes with area > 200 and w/h <= 1.6; None: on for MOT
            [authors' MOT evaluation].
        pixel_origin: Coordinate of the first pixel of box observations [MOTChallenge: 1].
        max_mask_area: Most location features per mask or pose; None: the task's
            [200 MOTS and PoseTrack, 1000 VIS].
        mask_box: Kalman box of a mask or pose: ``"mad"`` [paper] or ``"tight"``.
        min_keypoint_score: A keypoint is drawn into a pose's mask above this score [0].
        category_gating: A track only matches detections of its class; None: on for VIS.
        association: Other :class:`AssociationConfig` fields, over the preset's values.

    Which detections the agent sees is the environment's business (its ``min_score``).
    """

    task: str | None = None
    preset: str = "default"
    similarity: str | Callable[..., Any] = "rsm"
    use_motion: bool = True
    new_track_score: float = 0.5
    input_size: tuple[int, int] = MOT_INPUT_SIZE
    roi_size: tuple[int, int] = ROI_OUTPUT_SIZE
    roi_sampling_ratio: int = 2
    feature_cache: str | os.PathLike[str] | bool | None = True
    feature_cache_size: int | str | None = None
    output_filter: bool | None = None
    pixel_origin: float = MOT_PIXEL_ORIGIN
    max_mask_area: int | None = None
    mask_box: str = "mad"
    min_keypoint_score: float = 0.0
    category_gating: bool | None = None
    association: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        parent = getattr(super(), "__post_init__", None)
        if parent is not None:
            parent()
        if self.task is not None and self.task not in TASK_DEFAULTS:
            raise ValueError(f"unknown task {self.task!r}; valid tasks: {', '.join(TASKS)}")
        if self.preset not in PRESETS:
            raise ValueError(f"preset must be one of {', '.join(PRESETS)}, got {self.preset!r}")
        if self.mask_box not in MASK_BOX_MODES:
            raise ValueError(
                f"mask_box must be one of {', '.join(MASK_BOX_MODES)}, got {self.mask_box!r}")
        if self.max_mask_area is not None and self.max_mask_area < 1:
            raise ValueError(f"max_mask_area must be >= 1 or None, got {self.max_mask_area}")
        clash = sorted(set(self.association) & set(AGENT_LEVEL_FIELDS))
        if clash:
            raise ValueError(f"association={{{clash[0]!r}: ...}}: set it with the agent "
                             "option (use_motion, new_track_score, output_filter)")

    def settings(self, task: str, scores: ScoreRange | None = None) -> TaskSettings:
        """The settings of ``task``, thresholds on ``scores`` (None: as given); bad names raise."""
        try:
            defaults = TASK_DEFAULTS[task]
        except KeyError:
            raise ValueError(f"unknown task {task!r}; valid tasks: {', '.join(TASKS)}") from None
        new_track = self.new_track_score if scores is None \
            else scores.from_unit(self.new_track_score)
        preset = AssociationConfig.preset(self.preset, task)
        output: dict[str, Any] = {}
        if self.output_filter is not None:
            output = {"output_min_area": MOT_OUTPUT_MIN_AREA if self.output_filter else None,
                      "output_max_aspect": MOT_OUTPUT_MAX_ASPECT if self.output_filter else None}
        try:
            association = replace(preset, use_motion=self.use_motion, new_track_score=new_track,
                                  **output, **self.association)
        except TypeError as exc:
            valid = ", ".join(sorted(AssociationConfig.__dataclass_fields__))
            raise TypeError(f"bad association option ({exc}); valid fields: {valid}") from None
        return TaskSettings(
            task, defaults.observation, association,
            self.max_mask_area if self.max_mask_area is not None else defaults.max_mask_area,
            defaults.category_gating if self.category_gating is None else self.category_gating,
        )

    def association_config(self, task: str = "mot",
                           scores: ScoreRange | None = None) -> AssociationConfig:
        """The :class:`AssociationConfig` these options describe on ``task``."""
        return self.settings(task, scores).association


@dataclass(frozen=True)
class TaskSettings:
    """The ``unitrack`` agent's settings on one task (from :meth:`UniTrackConfig.settings`)."""

    task: str
    observation: str
    association: AssociationConfig
    max_mask_area: int | None
    category_gating: bool
