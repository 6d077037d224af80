"""The UniTrack MOT head (agent ``unitrack`` on box observations).

The box head is one mode of the association head in :mod:`unitrack_env.agents.heads.association`,
which serves boxes (MOT), masks (MOTS, VIS) and poses (PoseTrack) with the same agent. Per frame
on boxes (UniTrack paper, section 2.4 and appendix C.1):

1. Drop detections with a score below ``min_score`` (if set) or an empty box.
2. Letterbox the whole frame to the input size (default 1088 x 608) and run the appearance
   model once: a stride-8 feature map.
3. RoIAlign each detection box on that map into a tall 10 x 4 grid (the authors pass
   ``[4, 10]``, which reads as a transposed wide grid; a tall grid is the sensible shape for
   pedestrians), giving 40 location features of C channels; L2-normalise each location.
4. Associate with :class:`~unitrack_env.agents.primitives.association.Associator` (two-stage:
   appearance similarity fused with Kalman motion, then IoU; track life cycle) using the chosen
   similarity (RSM by default; CF, GF and GPF are the paper's baselines).
5. Act with the confirmed tracks matched in this frame, each with the box of the detection
   it matched (MOT output filter: area > 200 and w/h <= 1.6).

Defaults on MOT are the paper's setting plus four measured departures, each a field of
:class:`~unitrack_env.agents.primitives.association.AssociationConfig` documented with its
paper value in :data:`~unitrack_env.agents.primitives.association.MOT_ASSOCIATION`: the
matched detection's box is reported (code: the Kalman state); an appearance match must beat
every other acceptable pair of its track and detection by ``ambiguity_margin = 0.1`` in
cost, else the IoU stage decides (paper: no check); a tentative track is confirmed at
IoU > 0.5 (paper: 0.8); lost tracks take part in the IoU stage (as in the paper's
Algorithm 1; the authors' code leaves them out). ``paper_settings=True`` reproduces the
paper's setting exactly::

    make_agent("unitrack", paper_settings=True)

Frames with no detections skip the backbone entirely (the authors' code crashed on them).
Frame sizes may change between episodes: each frame is letterboxed on its own.

This module keeps the MOT names: :class:`UniTrackMOTAgent` and :class:`UniTrackMOTConfig`
are the association head's :class:`~unitrack_env.agents.heads.association.UniTrackAgent` and
:class:`~unitrack_env.agents.heads.association.UniTrackConfig`.

Example:
    >>> import gymnasium as gym, unitrack_env                    # doctest: +SKIP
    >>> from unitrack_env.agents import make_agent                             # doctest: +SKIP
    >>> env = gym.make("UniTrack/MOT16-v0")                       # doctest: +SKIP
    >>> agent = make_agent("unitrack", similarity="rsm")          # doctest: +SKIP
    >>> obs, info = env.reset(); agent.reset(obs, info)           # doctest: +SKIP
    >>> obs, reward, terminated, truncated, info = env.step(agent.act(obs))  # doctest: +SKIP
"""

from __future__ import annotations

from unitrack_env.agents.heads.association import (
    DEFAULT_MAX_TRACKS,
    MOT_OUTPUT_MAX_ASPECT,
    MOT_OUTPUT_MIN_AREA,
    MOT_PIXEL_ORIGIN,
    ROI_OUTPUT_SIZE,
    UniTrackAgent,
    UniTrackConfig,
)

UniTrackMOTAgent = UniTrackAgent
"""The ``unitrack`` agent (box, mask and pose association); its MOT name."""

UniTrackMOTConfig = UniTrackConfig
"""Options of the ``unitrack`` agent; its MOT name."""

__all__ = [
    "DEFAULT_MAX_TRACKS",
    "MOT_OUTPUT_MAX_ASPECT",
    "MOT_OUTPUT_MIN_AREA",
    "MOT_PIXEL_ORIGIN",
    "ROI_OUTPUT_SIZE",
    "UniTrackMOTAgent",
    "UniTrackMOTConfig",
]
