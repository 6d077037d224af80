"""Parameters of the association engine (:class:`AssociationConfig`) and its presets.

``paper()`` is the paper's setting of a task, ``mot()`` the ``unitrack`` agent's MOT default;
why each departure: ``docs/design-decisions.md``, "Association defaults (MOT)".
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .kalman import CHI2_95_4DOF, KalmanConfig
from .matching import APPEARANCE_WEIGHT_PAPER

MOT_OUTPUT_MIN_AREA: float = 200.0
"""MOT output filter of the authors' code: report only boxes with ``w * h`` above this."""

MOT_OUTPUT_MAX_ASPECT: float = 1.6
"""MOT output filter of the authors' code: report only boxes with ``w / h`` up to this
(pedestrians are tall; wide boxes are false positives)."""

PRESETS: tuple[str, ...] = ("default", "paper")
"""Names of :meth:`AssociationConfig.preset`: the agent's defaults, or the paper's setting."""

#: The paper's per-task values that differ from the dataclass defaults (authors' code where
#: the paper is silent; their IoU *distance* limits converted to IoUs).
_PAPER_TASK: dict[str, dict[str, object]] = {
    # chi-square gate; MOT output filter (area > 200, w/h <= 1.6)
    "mot": {"output_min_area": MOT_OUTPUT_MIN_AREA, "output_max_aspect": MOT_OUTPUT_MAX_ASPECT},
    # no gate (the code gates MOT only); confirmation and duplicates as MOT
    "mots": {"gate_threshold": None},
    # no gate; confirmed at IoU > 0.4 (code: 0.6 distance); duplicates at IoU > 0.8 (0.2)
    "vis": {"gate_threshold": None, "confirm_iou_threshold": 0.4, "duplicate_iou": 0.8},
    "posetrack": {"gate_threshold": None, "confirm_iou_threshold": 0.4, "duplicate_iou": 0.8},
}


@dataclass(frozen=True)
class AssociationConfig:
    """Parameters of :class:`Associator` (paper values unless said otherwise).

    Attributes:
        use_motion: Fuse the Kalman Mahalanobis distance into the stage-1 cost and gate with
            it; ``False`` is the paper's "w/o motion" (the filter still runs for the IoU stages).
        appearance_weight: ``lambda`` in ``lambda * C_a + (1 - lambda) * C_m``. Paper 0.99.
        gate_threshold: Squared-Mahalanobis gate of stage 1 (chi-square 0.95, 4 dof = 9.4877);
            ``None`` fuses without gating (the authors' MOTS/pose configs).
        appearance_threshold: Stage-1 matches need a fused cost below this. Code: 0.7.
        iou_threshold: Stage-2 matches need ``IoU > iou_threshold`` to the predicted box. 0.5.
        confirm_iou_threshold: A tentative track is confirmed by a detection with IoU above
            this. Paper (appendix C.1): 0.8.
        new_track_score: An unmatched detection starts a track when its score is at least
            this, on the detections' own scale. Code: 0.5.
        confirm_on_first_frame: Confirm tracks born on an episode's first frame at once (code).
        lost_seconds: Keep a lost track ``round(lost_seconds * frame_rate)`` frames. Paper: 1.
        duplicate_iou: An active and a lost track with IoU above this are duplicates; the
            younger is removed. Code: 0.15 as an IoU distance, i.e. 0.85.
        freeze_lost_height_velocity: Zero the height velocity of lost tracks before predicting
            (code, from JDE), so unobserved boxes do not grow without bound.
        iou_stage_includes_lost: Also offer lost tracks to the IoU stage (code: ``False``).
        report_filtered_box: Report the Kalman-filtered box of a matched track (code), not the
            detection's box.
        reid_threshold: Stricter stage-1 cost limit for re-finding *lost* tracks; ``None``
            (paper): ``appearance_threshold``.
        ambiguity_margin: Keep a stage-1 match only when every rival pair costs at least this
            much more (a ratio test); ambiguous pairs fall to the IoU stage. Paper: 0.
        appearance_momentum: ``0`` (paper) a track remembers its last observation; ``m > 0``
            the moving average ``m * memory + (1 - m) * observation`` (JDE: 0.9).
        output_min_area: When set, report only boxes with ``w * h`` above it (code MOT: 200).
        output_max_aspect: When set, report only boxes with ``w / h`` at most it (code: 1.6).
        kalman: Noise parameters of the Kalman filter.
    """

    use_motion: bool = True
    appearance_weight: float = APPEARANCE_WEIGHT_PAPER
    gate_threshold: float | None = CHI2_95_4DOF
    appearance_threshold: float = 0.7
    iou_threshold: float = 0.5
    confirm_iou_threshold: float = 0.8
    new_track_score: float = 0.5
    confirm_on_first_frame: bool = True
    lost_seconds: float = 1.0
    duplicate_iou: float = 0.85
    freeze_lost_height_velocity: bool = True
    iou_stage_includes_lost: bool = False
    report_filtered_box: bool = True
    reid_threshold: float | None = None
    ambiguity_margin: float = 0.0
    appearance_momentum: float = 0.0
    output_min_area: float | None = None
    output_max_aspect: float | None = None
    kalman: KalmanConfig = field(default_factory=KalmanConfig)

    def __post_init__(self) -> None:
        for name in ("appearance_weight", "iou_threshold", "confirm_iou_threshold",
                     "duplicate_iou"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"AssociationConfig.{name} must be in [0, 1], got {value!r}")
        if not self.appearance_threshold > 0:
            raise ValueError(
                "AssociationConfig.appearance_threshold must be positive, "
                f"got {self.appearance_threshold!r}"
            )
        if self.gate_threshold is not None and not self.gate_threshold > 0:
            raise ValueError(
                f"AssociationConfig.gate_threshold must be positive or None, "
                f"got {self.gate_threshold!r}"
            )
        if not 0.0 <= self.appearance_momentum < 1.0:
            raise ValueError("AssociationConfig.appearance_momentum must be in [0, 1), "
                             f"got {self.appearance_momentum!r}")
        if not (np.isfinite(self.lost_seconds) and self.lost_seconds >= 0):
            raise ValueError(
                f"AssociationConfig.lost_seconds must be >= 0, got {self.lost_seconds!r}"
            )

    @classmethod
    def paper(cls, task: str = "mot") -> AssociationConfig:
        """The paper's setting on ``task`` (``"mot"``, ``"mots"``, ``"vis"``, ``"posetrack"``)."""
        try:
            return cls(**_PAPER_TASK[task])  # type: ignore[arg-type]
        except KeyError:
            raise ValueError(f"unknown task {task!r}; valid tasks: "
                             f"{', '.join(_PAPER_TASK)}") from None

    @classmethod
    def mot(cls) -> AssociationConfig:
        """The ``unitrack`` agent's MOT default: the paper's with five measured departures.

        Why each: ``docs/design-decisions.md``, "Association defaults (MOT)".
        """
        return replace(cls.paper("mot"), report_filtered_box=False, ambiguity_margin=0.05,
                       appearance_momentum=0.95, confirm_iou_threshold=0.5,
                       iou_stage_includes_lost=True)

    @classmethod
    def preset(cls, name: str, task: str = "mot") -> AssociationConfig:
        """``"paper"``: :meth:`paper`; ``"default"``: :meth:`mot` on MOT, else :meth:`paper`."""
        if name not in PRESETS:
            raise ValueError(f"unknown preset {name!r}; valid presets: {', '.join(PRESETS)}")
        return cls.mot() if name == "default" and task == "mot" else cls.paper(task)
