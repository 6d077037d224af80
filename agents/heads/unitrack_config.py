"""Options of the ``unitrack`` association agent: one flat, typed config and its presets.

Every option is a field of :class:`UniTrackConfig` (``--agent-arg name=value``). The options
whose value differs by task or preset default to None and are filled once per task by
:meth:`UniTrackConfig.resolve` from :data:`PRESETS`, the one table of per-task values. Why
each default: ``docs/design-decisions.md``, "Association defaults (MOT)".
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from types import MappingProxyType
from typing import Any

from unitrack_env.score_range import ScoreRange

from ..appearance.letterboxing import MOT_INPUT_SIZE
from ..appearance.spec import AppearanceSpec
from ..primitives.association_config import AssociationConfig, check_association_values
from ..primitives.kalman import CHI2_95_4DOF, KalmanConfig
from ..primitives.mask_features import MAX_MASK_AREA_MOTS, MAX_MASK_AREA_VIS
from ..primitives.matching import APPEARANCE_WEIGHT_PAPER

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
class TaskValues:
    """The values of :class:`UniTrackConfig`'s per-task options (its None fields) on one task."""

    gate: bool = False
    output_filter: bool = False
    confirm_iou_threshold: float = 0.8
    duplicate_iou: float = 0.85
    report_filtered_box: bool = True
    iou_stage_includes_lost: bool = False
    ambiguity_margin: float = 0.0
    appearance_momentum: float = 0.0
    max_mask_area: int | None = None
    category_gating: bool = False


#: The paper's setting per task (the authors' code where the paper is silent; their IoU
#: *distance* limits converted to IoUs). The authors gate and filter the output on MOT only;
#: VIS and poses confirm at IoU > 0.4 (code: 0.6 distance) and drop duplicates at 0.8 (0.2).
#: The authors give no mask-area cap for poses; PoseTrack people are MOTS-sized.
_PAPER: Mapping[str, TaskValues] = MappingProxyType({
    "mot": TaskValues(gate=True, output_filter=True),
    "mots": TaskValues(max_mask_area=MAX_MASK_AREA_MOTS),
    "vis": TaskValues(confirm_iou_threshold=0.4, duplicate_iou=0.8,
                      max_mask_area=MAX_MASK_AREA_VIS, category_gating=True),
    "posetrack": TaskValues(confirm_iou_threshold=0.4, duplicate_iou=0.8,
                            max_mask_area=MAX_MASK_AREA_MOTS),
})

#: The agent's default: the paper's, with five measured departures on MOT (issue 11).
_DEFAULT: Mapping[str, TaskValues] = MappingProxyType({**_PAPER, "mot": replace(
    _PAPER["mot"], report_filtered_box=False, ambiguity_margin=0.05, appearance_momentum=0.95,
    confirm_iou_threshold=0.5, iou_stage_includes_lost=True)})

PRESETS: Mapping[str, Mapping[str, TaskValues]] = MappingProxyType(
    {"default": _DEFAULT, "paper": _PAPER})
"""Preset name -> task -> the values its None options take (read-only)."""


@dataclass(frozen=True)
class UniTrackConfig(AppearanceSpec):
    """Options of the ``unitrack`` agent: ``name: type = default`` [paper value].

    ``*``: None means the preset's value on the task (:data:`PRESETS`), written
    MOT / MOTS / VIS / PoseTrack; the default preset departs from the paper on MOT only.

    Appearance: weights="imagenet-lite0", arch, layer, remap="auto", device="cpu",
    runtime, stride, num_threads (torch threads while acting): see :class:`AppearanceSpec`.

    ``task: str | None = None``  mot / mots / vis / posetrack; None: the environment's.
    ``preset: str = "default"``  "default" (paper + 5 MOT departures) or "paper".
    ``similarity: str | callable = "rsm"`` [rsm]; "cf", "gf", "gpf" or ``(tracks, dets)``.
    ``input_size = (1088, 608)``  (width, height) of the letterboxed input [1088 x 608].
    ``roi_size = (10, 4)``, ``roi_sampling_ratio = 2``  RoIAlign grid and samples [same].
    ``pixel_origin: float = 1.0``  coordinate of the first pixel of boxes [MOTChallenge 1].
    ``feature_cache = True``  user cache folder, a folder, or False; ``feature_cache_size``.
    ``mask_box = "mad"`` [mad] or "tight"; ``min_keypoint_score = 0.0`` [0]: poses to masks.
    ``max_mask_area: int | None`` *  features per mask [- / 200 / 1000 / 200].
    ``category_gating: bool | None`` *  match within a class only [off / off / on / off].
    ``use_motion: bool = True``  fuse Kalman motion [True; False: paper's "w/o motion"].
    ``appearance_weight = 0.99``  lambda in lambda C_a + (1 - lambda) C_m [0.99].
    ``gate: bool | None`` *  Mahalanobis gate [on / off / off / off];
    ``gate_threshold = 9.4877``  its chi-square 0.95 limit [9.4877].
    ``appearance_threshold = 0.7``  stage-1 fused-cost limit [code 0.7].
    ``reid_threshold: float | None = None``  stricter limit for lost tracks; None: as above.
    ``ambiguity_margin: float | None`` *  stage-1 ratio test [0; default on MOT 0.05].
    ``appearance_momentum: float | None`` *  track memory average [0; default on MOT 0.95].
    ``iou_threshold = 0.5``  stage-2 IoU [0.5];
    ``iou_stage_includes_lost: bool | None`` *  [off; default on MOT on].
    ``confirm_iou_threshold: float | None`` *  [0.8 / 0.8 / 0.4 / 0.4; default on MOT 0.5].
    ``new_track_score = 0.5``  least score that starts a track, on 0..1 of the declared
    score range (``info["detection_scores"]``) [code 0.5].
    ``confirm_on_first_frame = True`` [code]; ``lost_seconds = 1.0`` [paper 1 s].
    ``duplicate_iou: float | None`` *  active/lost duplicates [0.85 / 0.85 / 0.8 / 0.8].
    ``freeze_lost_height_velocity = True`` [code]; ``kalman = KalmanConfig()`` [DeepSORT].
    ``report_filtered_box: bool | None`` *  Kalman box, not detection [on; default MOT off].
    ``output_filter: bool | None`` *  area > 200, w/h <= 1.6 [on / off / off / off].

    Which detections the agent sees is the environment's business (its ``min_score``).
    """

    task: str | None = None
    preset: str = "default"
    similarity: str | Callable[..., Any] = "rsm"
    input_size: tuple[int, int] = MOT_INPUT_SIZE
    roi_size: tuple[int, int] = ROI_OUTPUT_SIZE
    roi_sampling_ratio: int = 2
    pixel_origin: float = MOT_PIXEL_ORIGIN
    feature_cache: str | os.PathLike[str] | bool | None = True
    feature_cache_size: int | str | None = None
    mask_box: str = "mad"
    min_keypoint_score: float = 0.0
    max_mask_area: int | None = None
    category_gating: bool | None = None
    use_motion: bool = True
    appearance_weight: float = APPEARANCE_WEIGHT_PAPER
    gate: bool | None = None
    gate_threshold: float = CHI2_95_4DOF
    appearance_threshold: float = 0.7
    reid_threshold: float | None = None
    ambiguity_margin: float | None = None
    appearance_momentum: float | None = None
    iou_threshold: float = 0.5
    iou_stage_includes_lost: bool | None = None
    confirm_iou_threshold: float | None = None
    new_track_score: float = 0.5
    confirm_on_first_frame: bool = True
    lost_seconds: float = 1.0
    duplicate_iou: float | None = None
    freeze_lost_height_velocity: bool = True
    kalman: KalmanConfig = field(default_factory=KalmanConfig)
    report_filtered_box: bool | None = None
    output_filter: bool | None = None

    def __post_init__(self) -> None:
        """Check every value once, before anything is played (names and types: the CLI)."""
        if self.task is not None and self.task not in TASKS:
            raise ValueError(f"unknown task {self.task!r}; valid tasks: {', '.join(TASKS)}")
        if self.preset not in PRESETS:
            raise ValueError(f"preset must be one of {', '.join(PRESETS)}, got {self.preset!r}")
        if self.mask_box not in MASK_BOX_MODES:
            raise ValueError(
                f"mask_box must be one of {', '.join(MASK_BOX_MODES)}, got {self.mask_box!r}")
        if self.max_mask_area is not None and self.max_mask_area < 1:
            raise ValueError(f"max_mask_area must be >= 1 or None, got {self.max_mask_area}")
        check_association_values(self, "UniTrackConfig")

    @classmethod
    def paper(cls, **options: Any) -> UniTrackConfig:
        """The paper's setting on every task (``--agent-arg preset=paper``), plus ``options``."""
        return cls(preset="paper", **options)

    def resolve(self, task: str | None = None) -> UniTrackConfig:
        """This config on ``task`` (default: its own, else MOT): every None option filled."""
        task = task or self.task or "mot"
        if task not in TASKS:
            raise ValueError(f"unknown task {task!r}; valid tasks: {', '.join(TASKS)}")
        values = PRESETS[self.preset][task]
        unset = {f.name: getattr(values, f.name) for f in fields(TaskValues)
                 if getattr(self, f.name) is None}
        return replace(self, task=task, **unset)

    def association(self, scores: ScoreRange | None = None) -> AssociationConfig:
        """The association engine's parameters; thresholds on ``scores`` (None: as given).

        Call it on a :meth:`resolve`-d config (the per-task options set).
        """
        if self.task is None:
            raise ValueError("resolve(task) the config before asking for its association")
        raw = self.new_track_score if scores is None else scores.from_unit(self.new_track_score)
        return AssociationConfig(
            use_motion=self.use_motion, appearance_weight=self.appearance_weight,
            gate_threshold=self.gate_threshold if self.gate else None,
            appearance_threshold=self.appearance_threshold, iou_threshold=self.iou_threshold,
            confirm_iou_threshold=self.confirm_iou_threshold,  # type: ignore[arg-type]
            new_track_raw_score=raw, confirm_on_first_frame=self.confirm_on_first_frame,
            lost_seconds=self.lost_seconds,
            duplicate_iou=self.duplicate_iou,  # type: ignore[arg-type]
            freeze_lost_height_velocity=self.freeze_lost_height_velocity,
            iou_stage_includes_lost=bool(self.iou_stage_includes_lost),
            report_filtered_box=bool(self.report_filtered_box),
            reid_threshold=self.reid_threshold,
            ambiguity_margin=self.ambiguity_margin,  # type: ignore[arg-type]
            appearance_momentum=self.appearance_momentum,  # type: ignore[arg-type]
            output_min_area=MOT_OUTPUT_MIN_AREA if self.output_filter else None,
            output_max_aspect=MOT_OUTPUT_MAX_ASPECT if self.output_filter else None,
            kalman=self.kalman,
        )
