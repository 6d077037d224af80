"""Parameters of the association engine (:class:`AssociationConfig`) and their checks.

The engine's own record, in the detections' raw score scale; the ``unitrack`` agent builds
it from its flat options (:class:`~unitrack_env.agents.heads.unitrack_config.UniTrackConfig`,
where the paper's per-task values and the agent's defaults are).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .kalman import CHI2_95_4DOF, KalmanConfig
from .matching import APPEARANCE_WEIGHT_PAPER


def check_association_values(values: Any, owner: str) -> None:
    """Raise ValueError naming ``owner.field`` for an out-of-range association value.

    ``values`` has the fields as attributes; a field that is None or absent is not checked.
    """
    def value(name: str) -> Any:
        return getattr(values, name, None)

    for name in ("appearance_weight", "iou_threshold", "confirm_iou_threshold",
                 "duplicate_iou"):
        if value(name) is not None and not 0.0 <= value(name) <= 1.0:
            raise ValueError(f"{owner}.{name} must be in [0, 1], got {value(name)!r}")
    for name in ("appearance_threshold", "gate_threshold"):
        if value(name) is not None and not value(name) > 0:
            raise ValueError(f"{owner}.{name} must be positive, got {value(name)!r}")
    momentum = value("appearance_momentum")
    if momentum is not None and not 0.0 <= momentum < 1.0:
        raise ValueError(f"{owner}.appearance_momentum must be in [0, 1), got {momentum!r}")
    lost = value("lost_seconds")
    if lost is not None and not (np.isfinite(lost) and lost >= 0):
        raise ValueError(f"{owner}.lost_seconds must be >= 0, got {lost!r}")


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
        new_track_raw_score: An unmatched detection starts a track when its score is at
            least this, on the detections' own (raw) scale. Code: 0.5.
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
    new_track_raw_score: float = 0.5
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
        check_association_values(self, "AssociationConfig")
