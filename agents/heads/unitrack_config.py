"""Options of the ``unitrack`` association agent and its per-task settings table.

:class:`UniTrackConfig` holds the user's options (the appearance model's fields come from
:class:`~unitrack_env.agents.appearance.spec.AppearanceSpec`); :data:`TASK_DEFAULTS` is the
per-task table; :meth:`UniTrackConfig.settings` resolves both into one
:class:`TaskSettings` per task, once per episode.

Task defaults (:data:`TASK_DEFAULTS`) follow the authors' per-task settings; where their code
passes a threshold as an IoU *distance* (``1 - IoU``), it is converted to an IoU here (the
MOT values are explained in :class:`~unitrack_env.agents.primitives.association.AssociationConfig`):

* ``mot``: chi-square gate 9.4877; duplicates at IoU > 0.85 (code: 0.15 distance); MOT
  output filter; plus five measured departures from the paper
  (:data:`~unitrack_env.agents.primitives.association.MOT_ASSOCIATION`: detection boxes
  reported, a moving average (momentum 0.95) of each track's appearance, an ambiguity margin
  of 0.05 on appearance matches, confirmation at IoU > 0.5 instead of 0.8, lost tracks in
  the IoU stage); ``paper_settings=True`` drops them.
* ``mots``: no gate (the code gates MOT only); confirmation and duplicates as MOT;
  at most 200 locations per mask.
* ``vis``: no gate; confirmed at IoU > 0.4 (code: 0.6 distance); duplicates at IoU > 0.8
  (code: 0.2 distance); at most 1000 locations per mask; tracks gated by class.
* ``posetrack``: as VIS without classes; at most 200 locations per drawn pose (the authors
  give no cap for poses; PoseTrack people are MOTS-sized).

Measured on the synthetic sets at 1088 x 608 (IDF1 per sequence unless said): the MAD box
beats the tight box on PoseTrack (0.898 vs 0.817 on 900002) and VIS (AP 0.571 vs 0.497 on
syn-01) and is slightly behind it on MOTS (0.874 vs 0.904 on SYN-02); confirming at 0.4
rather than 0.8 gives PoseTrack MOTA 0.807 / 0.852 instead of 0.770 / 0.833; without the
gate PoseTrack 900003 has 4 id switches instead of 16.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

from ..appearance.letterboxing import MOT_INPUT_SIZE
from ..appearance.spec import AppearanceSpec
from ..primitives.association_config import (
    MOT_ASSOCIATION,
    AssociationConfig,
)
from ..primitives.mask_features import MAX_MASK_AREA_MOTS, MAX_MASK_AREA_VIS

ROI_OUTPUT_SIZE: tuple[int, int] = (10, 4)
"""(rows, columns) of the RoIAlign grid per box: 40 location features (tall, for people)."""

MOT_PIXEL_ORIGIN: float = 1.0
"""MOTChallenge boxes are 1-based (the top-left pixel is (1, 1)); subtracting this maps them
to continuous 0-based image coordinates before pooling features."""

MOT_OUTPUT_MIN_AREA: float = 200.0
"""MOT output filter of the authors' code: report only boxes with ``w * h`` above this."""

MOT_OUTPUT_MAX_ASPECT: float = 1.6
"""MOT output filter of the authors' code: report only boxes with ``w / h`` up to this
(pedestrians are tall; wide boxes are false positives)."""

TASKS: tuple[str, ...] = ("mot", "mots", "vis", "posetrack")
"""Association tasks the agent plays."""

MASK_BOX_MODES: tuple[str, ...] = ("mad", "tight")
"""How a mask becomes a Kalman box: the paper's mean-absolute-deviation box, or the tight box."""


@dataclass(frozen=True)
class TaskDefaults:
    """Per-task defaults of the ``unitrack`` agent (see the module docstring's table).

    Attributes:
        observation: ``"boxes"``, ``"masks"`` or ``"poses"``.
        association: :class:`AssociationConfig` fields that differ from its defaults.
        output_filter: Apply the MOT output filter (area > 200, w/h <= 1.6).
        max_mask_area: Most location features per mask or pose (None for boxes).
        category_gating: A track only matches detections of its class (VIS).
    """

    observation: str
    association: Mapping[str, Any] = field(default_factory=dict)
    output_filter: bool = False
    max_mask_area: int | None = None
    category_gating: bool = False


_POSE_VIS_ASSOCIATION: Mapping[str, Any] = MappingProxyType({
    # Authors' pose/VIS code: no chi-square gate; unconfirmed tracks matched with an IoU
    # distance below 0.6 (IoU > 0.4); duplicates at an IoU distance below 0.2 (IoU > 0.8).
    "gate_threshold": None,
    "confirm_iou_threshold": 0.4,
    "duplicate_iou": 0.8,
})

TASK_DEFAULTS: Mapping[str, TaskDefaults] = MappingProxyType({
    # Measured departures from the paper on MOT (each documented beside its paper value in
    # MOT_ASSOCIATION); ``paper_settings=True`` drops them.
    "mot": TaskDefaults("boxes", MOT_ASSOCIATION, output_filter=True),
    # Authors' MOTS code: no chi-square gate (it is MOT-only); confirmation and duplicate
    # thresholds as for MOT.
    "mots": TaskDefaults("masks", {"gate_threshold": None}, max_mask_area=MAX_MASK_AREA_MOTS),
    "vis": TaskDefaults("masks", _POSE_VIS_ASSOCIATION, max_mask_area=MAX_MASK_AREA_VIS,
                        category_gating=True),
    # The authors give no mask-area cap for poses; PoseTrack people are MOTS-sized.
    "posetrack": TaskDefaults("poses", _POSE_VIS_ASSOCIATION, max_mask_area=MAX_MASK_AREA_MOTS),
})
"""Task name -> :class:`TaskDefaults` (read-only)."""


@dataclass(frozen=True)
class UniTrackConfig(AppearanceSpec):
    """Options of the ``unitrack`` agent.

    The appearance model's options are :class:`AppearanceSpec`'s (``weights``, ``arch``,
    ``layer``, ``remap``, ``device``, ``runtime``, and ``num_threads``: torch threads while the
    agent acts, backbone and similarity, restored afterwards; 1 is much faster when several
    processes share the cores).

    Attributes:
        task: ``"mot"``, ``"mots"``, ``"vis"`` or ``"posetrack"``; None: the environment's
            (``info["task"]`` at reset; without it, the observation's keys, see
            :func:`~unitrack_env.agents.primitives.adapters.detect_task`). Selects
            :data:`TASK_DEFAULTS`.
        similarity: ``"rsm"`` (paper), ``"cf"``, ``"gf"`` (boxes only), ``"gpf"`` (appendix D
            baselines), or a callable ``(tracks, detections) -> (N, M) similarity``.
        use_motion: Fuse Kalman motion into the appearance stage (False: the paper's
            appearance-only "w/o motion" setting; the IoU stage still runs).
        input_size: ``(width, height)`` of the letterboxed network input (JDE: 1088 x 608).
        roi_size: ``(rows, columns)`` of the RoIAlign grid of a box.
        roi_sampling_ratio: Bilinear samples per RoIAlign bin and axis (boxes and masks).
        feature_cache: The on-disk feature cache
            (:mod:`~unitrack_env.agents.appearance.feature_cache`): True (default) the user
            cache folder (``$UNITRACK_FEATURE_CACHE``; ``off`` there turns the default off),
            a folder, or False / None for none. Entries are addressed by model, input size
            and frame content, so any sequence, data set or head with the same frames shares
            them; the stored float16 values are used warm or cold alike.
        feature_cache_size: Cap of the cache folder, bytes or text such as ``"10GiB"`` (least
            recently used entries are evicted); None: ``$UNITRACK_FEATURE_CACHE_MAX`` or
            10 GiB.
        min_score: Ignore detections scored below this (None: keep all). Detection scores
            are benchmark-specific (MOT17 FRCNN in [0, 1], MOT15 unbounded).
        new_track_score: Least score of a detection that starts a track (authors' code 0.5).
        output_filter: Report only boxes with area > 200 and w/h <= 1.6 (authors' MOT
            evaluation, meant for pedestrians); None: the task's default (on for MOT only).
        pixel_origin: Coordinate of the first pixel in box observations (MOTChallenge: 1).
            Masks and poses are 0-based pixel arrays / continuous pixels.
        max_mask_area: Most location features per mask or pose (cap by rescaling); None:
            the task's default (200 MOTS and PoseTrack, 1000 VIS).
        mask_box: Kalman box of a mask or pose: ``"mad"`` (paper, mean absolute deviation)
            or ``"tight"`` (the tight box).
        min_keypoint_score: A keypoint is drawn into a pose's mask when its score is above
            this (0 marks keypoints the detector did not find).
        category_gating: A track only matches detections of its class; None: the task's
            default (on for VIS, which has classes).
        paper_settings: Reproduce the paper's association setting exactly (the authors' code
            where the paper gives no value): the task defaults' measured departures
            (:data:`~unitrack_env.agents.primitives.association.MOT_ASSOCIATION`) are not
            applied. Explicit ``association`` fields still override.
        association: Any other :class:`AssociationConfig` fields (thresholds, lambda, ...);
            they override the task's defaults.
    """

    task: str | None = None
    similarity: str | Callable[..., Any] = "rsm"
    use_motion: bool = True
    input_size: tuple[int, int] = MOT_INPUT_SIZE
    roi_size: tuple[int, int] = ROI_OUTPUT_SIZE
    roi_sampling_ratio: int = 2
    feature_cache: str | os.PathLike[str] | bool | None = True
    feature_cache_size: int | str | None = None
    min_score: float | None = None
    new_track_score: float = 0.5
    output_filter: bool | None = None
    pixel_origin: float = MOT_PIXEL_ORIGIN
    max_mask_area: int | None = None
    mask_box: str = "mad"
    min_keypoint_score: float = 0.0
    category_gating: bool | None = None
    paper_settings: bool = False
    association: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        parent = getattr(super(), "__post_init__", None)
        if parent is not None:
            parent()
        if self.task is not None and self.task not in TASK_DEFAULTS:
            raise ValueError(f"unknown task {self.task!r}; valid tasks: {', '.join(TASKS)}")
        if self.mask_box not in MASK_BOX_MODES:
            raise ValueError(
                f"mask_box must be one of {', '.join(MASK_BOX_MODES)}, got {self.mask_box!r}")
        if self.max_mask_area is not None and self.max_mask_area < 1:
            raise ValueError(f"max_mask_area must be >= 1 or None, got {self.max_mask_area}")

    def settings(self, task: str) -> TaskSettings:
        """The settings of ``task``: its :data:`TASK_DEFAULTS` row under these options.

        Raises:
            ValueError: An unknown task.
            TypeError: An unknown ``association`` field (the message lists the valid ones).
        """
        try:
            defaults = TASK_DEFAULTS[task]
        except KeyError:
            raise ValueError(f"unknown task {task!r}; valid tasks: {', '.join(TASKS)}") from None
        output_filter = defaults.output_filter if self.output_filter is None \
            else self.output_filter
        base = AssociationConfig(
            use_motion=self.use_motion,
            new_track_score=self.new_track_score,
            output_min_area=MOT_OUTPUT_MIN_AREA if output_filter else None,
            output_max_aspect=MOT_OUTPUT_MAX_ASPECT if output_filter else None,
        )
        departures = {} if self.paper_settings and task == "mot" else dict(defaults.association)
        try:
            association = replace(base, **{**departures, **self.association})
        except TypeError as exc:
            valid = ", ".join(sorted(AssociationConfig.__dataclass_fields__))
            raise TypeError(f"bad association option ({exc}); valid fields: {valid}") from None
        return TaskSettings(
            task, defaults.observation, association,
            self.max_mask_area if self.max_mask_area is not None else defaults.max_mask_area,
            defaults.category_gating if self.category_gating is None else self.category_gating,
        )

    def association_config(self, task: str = "mot") -> AssociationConfig:
        """The :class:`AssociationConfig` these options describe on ``task``."""
        return self.settings(task).association

    def max_mask_area_for(self, task: str) -> int | None:
        """The mask-area cap on ``task`` (``settings(task).max_mask_area``)."""
        return self.settings(task).max_mask_area


@dataclass(frozen=True)
class TaskSettings:
    """The ``unitrack`` agent's settings on one task (resolved by :meth:`UniTrackConfig.settings`).

    Attributes:
        task: The task.
        observation: ``"boxes"``, ``"masks"`` or ``"poses"``.
        association: The association engine's parameters.
        max_mask_area: Most location features per mask or pose (None: no cap).
        category_gating: A track only matches detections of its class.
    """

    task: str
    observation: str
    association: AssociationConfig
    max_mask_area: int | None
    category_gating: bool
