"""Parameters of the association engine (:class:`AssociationConfig`) and its presets.

:meth:`AssociationConfig.paper` is the UniTrack paper's setting of a task (the authors' code
where the paper is silent); :meth:`AssociationConfig.mot` is the ``unitrack`` agent's MOT
default: the paper's with five measured departures. Why each departure, with the tables and
commands that chose it: ``docs/design-decisions.md``, "Association defaults (MOT)".
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
            it. ``False`` is the paper's "w/o motion" setting (appearance cost alone in stage
            1); the Kalman filter still runs for the IoU stages, as in the authors' code.
        appearance_weight: ``lambda`` in ``lambda * C_a + (1 - lambda) * C_m``. Paper 0.99;
            the authors' MOT config uses 0.98.
        gate_threshold: Squared-Mahalanobis gate of stage 1 (chi-square 0.95, 4 dof =
            9.4877); ``None`` fuses without gating (the authors' MOTS/pose configs).
        appearance_threshold: A stage-1 match is accepted when its fused cost is below this
            value. Authors' code: 0.7 (the paper gives no number).
        iou_threshold: A stage-2 match is accepted when ``IoU > iou_threshold`` between the
            Kalman-predicted track box and the detection. Authors' code: 0.5.
        confirm_iou_threshold: A tentative track is confirmed by a detection with
            ``IoU > confirm_iou_threshold`` to its box. Paper (appendix C.1): the IoU between
            the consecutive boxes must be at least 0.8 (the default). The authors' code passes
            0.7 as an IoU *distance* limit, i.e. accepts ``IoU > 0.3``; reading that 0.7 as
            an IoU gives 0.7.
        new_track_score: A detection left unmatched starts a track when its score is at
            least this value, on the detections' own scale. Authors' code: 0.5 (their
            detector's confidence); the ``unitrack`` agent states it on 0..1 of the
            environment's declared score range.
        confirm_on_first_frame: Tracks born on the first frame of an episode are confirmed
            at once (authors' code; the paper is silent). Without it every object would be
            missed on frame 1.
        lost_seconds: A lost track is kept for ``round(lost_seconds * frame_rate)`` frames
            after its last match (paper: 1 second; code: ``frame_rate / 30 * 30`` frames).
        duplicate_iou: An active and a lost track with ``IoU > duplicate_iou`` are treated
            as duplicates and the younger is removed. The authors' code passes 0.15 as an
            IoU *distance* limit, i.e. ``IoU > 0.85``; that is the default (read as an IoU,
            0.15 would merge neighbours in a crowd).
        freeze_lost_height_velocity: Set the height velocity of lost tracks to 0 before
            predicting (authors' code, from JDE), so that unobserved boxes do not grow or
            shrink without bound.
        iou_stage_includes_lost: Also offer lost tracks to the IoU stage. The paper's
            Algorithm 1 does not distinguish lost tracks; the authors' code offers only
            confirmed, currently tracked ones (default ``False``), since a lost track's
            predicted box drifts.
        report_filtered_box: Report the Kalman-filtered box of a matched track (authors'
            code). ``False`` reports the matched detection's box unchanged.
        reid_threshold: When set, a *lost* track is re-found in stage 1 only when its fused
            cost is below this (stricter than ``appearance_threshold``): re-identifying a
            person after a gap needs more evidence than following them from the previous
            frame. ``None`` (paper and code): lost tracks use ``appearance_threshold``.
        ambiguity_margin: A stage-1 match is kept only when every other acceptable pair of
            its track and of its detection costs at least this much more (a ratio test);
            ambiguous pairs fall to the IoU stage, where overlap with the predicted box
            decides. ``0`` (paper and code): no check.
        appearance_momentum: What a track remembers of its appearance after a match:
            ``0`` (paper; authors' code ``curr_feat``) the matched observation's payload;
            ``m > 0`` the location-wise moving average ``m * memory + (1 - m) * observation``
            (JDE's embedding smoothing, momentum 0.9; see
            :mod:`~unitrack_env.agents.primitives.appearance_memory`). Payloads of different
            shapes (masks of different sizes) keep the newest.
        output_min_area: When set, only report boxes with ``w * h > output_min_area``
            (authors' MOT evaluation: 200).
        output_max_aspect: When set, only report boxes with ``w / h <= output_max_aspect``
            (authors' MOT evaluation: 1.6, i.e. no wide boxes for pedestrians).
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

        The detection's box is reported, tracks remember a moving average of their
        appearance (momentum 0.95), an appearance match must win by a margin of 0.05, a
        tentative track is confirmed at IoU > 0.5 (paper 0.8) and lost tracks take part in
        the IoU stage: chosen on PETS09-S2L1, the MOT17 clips and the synthetic scenes
        together (``docs/design-decisions.md``).
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
