"""The MOT names of the ``unitrack`` agent (box association is one of its tasks).

:class:`UniTrackMOTAgent` and :class:`UniTrackMOTConfig` are
:class:`~unitrack_env.agents.heads.association.UniTrackAgent` and
:class:`~unitrack_env.agents.heads.unitrack_config.UniTrackConfig`; the MOT defaults are
:meth:`~unitrack_env.agents.primitives.association_config.AssociationConfig.mot`
(``preset="paper"`` for the paper's setting).
"""

from __future__ import annotations

from typing import Any

from unitrack_env.agents.heads.association import UniTrackAgent
from unitrack_env.agents.heads.unitrack_config import (
    MOT_PIXEL_ORIGIN,
    ROI_OUTPUT_SIZE,
    UniTrackConfig,
)
from unitrack_env.agents.primitives.adapters import default_max_tracks
from unitrack_env.agents.primitives.association_config import (
    MOT_OUTPUT_MAX_ASPECT,
    MOT_OUTPUT_MIN_AREA,
)

UniTrackMOTAgent = UniTrackAgent
"""The ``unitrack`` agent (box, mask and pose association); its MOT name."""

UniTrackMOTConfig = UniTrackConfig
"""Options of the ``unitrack`` agent; its MOT name."""

__all__ = [
    "MOT_OUTPUT_MAX_ASPECT",
    "MOT_OUTPUT_MIN_AREA",
    "MOT_PIXEL_ORIGIN",
    "ROI_OUTPUT_SIZE",
    "UniTrackMOTAgent",
    "UniTrackMOTConfig",
]


def __getattr__(name: str) -> Any:
    """``DEFAULT_MAX_TRACKS``: the MOT environments' default action capacity."""
    if name == "DEFAULT_MAX_TRACKS":
        return default_max_tracks("mot")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
