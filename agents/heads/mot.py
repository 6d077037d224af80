"""The UniTrack MOT head: box association with the shared appearance model (agent ``unitrack``).

Per frame (UniTrack paper, section 2.4 and appendix C.1; facts about the authors' code in
``OFFICIAL-CODE-FACTS.md``, "Association"):

1. Drop detections with a score below ``min_score`` (if set) or an empty box.
2. Letterbox the whole frame to the input size (default 1088 x 608) and run the appearance
   model once: a stride-8 feature map.
3. RoIAlign each detection box on that map into a tall 10 x 4 grid (the authors pass
   ``[4, 10]``, which reads as a transposed wide grid; a tall grid is the sensible shape for
   pedestrians), giving 40 location features of C channels; L2-normalise each location.
4. Associate with :class:`~agents.primitives.association.Associator` (two-stage: appearance
   similarity fused with Kalman motion, then IoU; track life cycle) using the chosen
   similarity (RSM by default; CF, GF and GPF are the paper's baselines).
5. Act with the confirmed tracks matched in this frame.

Frames with no detections skip the backbone entirely (the authors' code crashed on them).
Frame sizes may change between episodes: each frame is letterboxed on its own.

Example:
    >>> import gymnasium as gym, unitrack_env                    # doctest: +SKIP
    >>> from agents import make_agent                             # doctest: +SKIP
    >>> env = gym.make("UniTrack/MOT16-v0")                       # doctest: +SKIP
    >>> agent = make_agent("unitrack", similarity="rsm")          # doctest: +SKIP
    >>> obs, info = env.reset(); agent.reset(obs, info)           # doctest: +SKIP
    >>> obs, reward, terminated, truncated, info = env.step(agent.act(obs))  # doctest: +SKIP
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from agents.appearance import (
    MOT_INPUT_SIZE,
    AppearanceModel,
    CachedAppearanceModel,
    letterbox,
)
from agents.base import Agent
from agents.primitives.association import AssociationConfig, Associator
from agents.primitives.roi_align import roi_align
from agents.primitives.similarity import SIMILARITIES
from unitrack_env.geometry import xywh_to_xyxy
from unitrack_env.spaces import pack_tracks, unpack_detections

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

DEFAULT_MAX_TRACKS: int = 512
"""Default action capacity (the MOTChallenge environments' default ``max_tracks``)."""


@dataclass(frozen=True)
class UniTrackMOTConfig:
    """Options of the ``unitrack`` MOT agent.

    Attributes:
        weights: Appearance-model weights (see :class:`~agents.appearance.AppearanceModel`):
            ``"imagenet-lite0"`` (default, offline), ``"random"``, a checkpoint path, ...
        arch: Backbone architecture; None: the weights' own.
        layer: Output layer; None: the architecture's default stride-8 layer.
        similarity: ``"rsm"`` (paper), ``"cf"``, ``"gf"``, ``"gpf"`` (appendix D baselines), or
            a callable ``(tracks, detections) -> (N, M) similarity``.
        use_motion: Fuse Kalman motion into the appearance stage (False: the paper's
            appearance-only "w/o motion" setting; the IoU stage still runs).
        input_size: ``(width, height)`` of the letterboxed network input (JDE: 1088 x 608).
        roi_size: ``(rows, columns)`` of the RoIAlign grid.
        roi_sampling_ratio: Bilinear samples per RoIAlign bin and axis.
        feature_cache: Directory of an on-disk feature cache (None: no cache).
        min_score: Ignore detections scored below this (None: keep all). Detection scores
            are benchmark-specific (MOT17 FRCNN in [0, 1], MOT15 unbounded).
        new_track_score: Least score of a detection that starts a track (authors' code 0.5).
        output_filter: Report only boxes with area > 200 and w/h <= 1.6 (authors' MOT
            evaluation; meant for pedestrians).
        pixel_origin: Coordinate of the first pixel in the detection boxes (MOTChallenge: 1).
        device: Torch device of the appearance model.
        num_threads: Torch threads while the agent acts (backbone and similarity; restored
            afterwards). None: torch's current setting. 1 is much faster when several
            processes share the cores (thread oversubscription).
        association: Any other :class:`AssociationConfig` fields (thresholds, lambda, ...).
    """

    weights: str = "imagenet-lite0"
    arch: str | None = None
    layer: str | None = None
    similarity: str | Callable[..., Any] = "rsm"
    use_motion: bool = True
    input_size: tuple[int, int] = MOT_INPUT_SIZE
    roi_size: tuple[int, int] = ROI_OUTPUT_SIZE
    roi_sampling_ratio: int = 2
    feature_cache: str | os.PathLike[str] | None = None
    min_score: float | None = None
    new_track_score: float = 0.5
    output_filter: bool = True
    pixel_origin: float = MOT_PIXEL_ORIGIN
    device: str = "cpu"
    num_threads: int | None = None
    association: dict[str, Any] = field(default_factory=dict)

    def association_config(self) -> AssociationConfig:
        """The :class:`AssociationConfig` these options describe."""
        base = AssociationConfig(
            use_motion=self.use_motion,
            new_track_score=self.new_track_score,
            output_min_area=MOT_OUTPUT_MIN_AREA if self.output_filter else None,
            output_max_aspect=MOT_OUTPUT_MAX_ASPECT if self.output_filter else None,
        )
        try:
            return replace(base, **self.association)
        except TypeError as exc:
            valid = ", ".join(sorted(AssociationConfig.__dataclass_fields__))
            raise TypeError(f"bad association option ({exc}); valid fields: {valid}") from None


class UniTrackMOTAgent(Agent, name="unitrack", tasks=("mot",)):
    """UniTrack's MOT head: RSM (or a baseline similarity) + Kalman + two-stage association.

    Args:
        max_tracks: Action capacity; must equal the environment's ``max_tracks``.
        appearance_model: A ready :class:`~agents.appearance.AppearanceModel` to share between
            agents (then ``weights``/``arch``/``layer``/``device``/``num_threads`` are
            ignored).
        **options: Fields of :class:`UniTrackMOTConfig`.

    Attributes:
        config: The options.
        model: The appearance model (possibly wrapped by the feature cache).
        associator: The association engine (its state is the agent's episode state).
    """

    def __init__(
        self,
        max_tracks: int = DEFAULT_MAX_TRACKS,
        *,
        appearance_model: AppearanceModel | None = None,
        **options: Any,
    ) -> None:
        try:
            self.config = UniTrackMOTConfig(**options)
        except TypeError as exc:
            valid = ", ".join(sorted(UniTrackMOTConfig.__dataclass_fields__))
            raise TypeError(f"unitrack: {exc}; valid options: {valid}") from None
        cfg = self.config
        self.max_tracks = int(max_tracks)
        if callable(cfg.similarity):
            self._similarity: Callable[..., Any] = cfg.similarity
        else:
            self._similarity = SIMILARITIES[cfg.similarity]
        base = appearance_model or AppearanceModel(
            cfg.weights, arch=cfg.arch, layer=cfg.layer, device=cfg.device,
            num_threads=cfg.num_threads,
        )
        self.appearance = base
        self.model: AppearanceModel | CachedAppearanceModel = (
            CachedAppearanceModel(base, cfg.feature_cache) if cfg.feature_cache else base
        )
        self.associator: Associator[torch.Tensor] = Associator(
            self._similarity, cfg.association_config()
        )
        self._sequence = ""
        self._frame_index = 0

    # ------------------------------------------------------------------ episode
    def reset(self, observation: Any, info: dict[str, Any]) -> None:
        """Forget all tracks and ids; read ``frame_rate`` (and the sequence name) from info."""
        frame_rate = info.get("frame_rate")
        self.associator.reset(frame_rate=float(frame_rate) if frame_rate else None)
        self._sequence = str(info.get("sequence", ""))
        # act() numbers frames from the reset frame (the benchmark's index, usually 1).
        self._frame_index = int(info.get("frame_index", 1)) - 1

    def act(self, observation: dict[str, Any]) -> dict[str, Any]:
        """Track one frame; return the confirmed tracks matched in it."""
        with _torch_threads(self.config.num_threads):
            return self._act(observation)

    def _act(self, observation: dict[str, Any]) -> dict[str, Any]:
        self._frame_index += 1
        boxes, scores = unpack_detections(observation)
        boxes = np.asarray(boxes, dtype=np.float64)
        scores = np.asarray(scores, dtype=np.float64)
        keep = np.all(np.isfinite(boxes), axis=1) & (boxes[:, 2] > 0) & (boxes[:, 3] > 0)
        keep &= np.isfinite(scores)
        if self.config.min_score is not None:
            keep &= scores >= self.config.min_score
        boxes, scores = boxes[keep], scores[keep]
        payloads = self.box_features(observation["frame"], boxes) if len(boxes) else []
        outputs = self.associator.step(boxes, scores, payloads)
        return pack_tracks(
            [o.track_id for o in outputs],
            np.array([o.box for o in outputs]).reshape(-1, 4),
            self.max_tracks,
        )

    # ------------------------------------------------------------------ features
    def feature_map(self, frame: np.ndarray) -> tuple[torch.Tensor, Any]:
        """Letterbox ``frame`` and return its ``(1, C, h, w)`` feature map and the letterbox."""
        boxed = letterbox(np.ascontiguousarray(frame), tuple(self.config.input_size))
        if isinstance(self.model, CachedAppearanceModel):
            if not self._sequence:
                raise ValueError(
                    "the feature cache needs the sequence name: call reset(observation, info) "
                    "with the environment's info (it holds 'sequence') before act()"
                )
            fmap = self.model.features(
                boxed.image, sequence=self._sequence, frames=self._frame_index
            )
        else:
            fmap = self.model.features(boxed.image)
        return fmap, boxed

    def box_features(self, frame: np.ndarray, boxes_xywh: np.ndarray) -> list[torch.Tensor]:
        """L2-normalised location features ``(rows * cols, C)`` of each box of one frame.

        Args:
            frame: uint8 RGB ``(H, W, 3)`` frame.
            boxes_xywh: ``(n, 4)`` boxes in the observation's coordinates.
        """
        fmap, boxed = self.feature_map(frame)
        xyxy = xywh_to_xyxy(boxes_xywh) - self.config.pixel_origin
        rois = torch.as_tensor(boxed.boxes_to_features(xyxy, self.appearance.stride),
                               dtype=fmap.dtype)
        pooled = roi_align(
            fmap, rois, tuple(self.config.roi_size), spatial_scale=1.0,
            sampling_ratio=self.config.roi_sampling_ratio,
        )  # (n, C, rows, cols)
        locations = pooled.flatten(2).transpose(1, 2)  # (n, rows * cols, C), row-major
        locations = F.normalize(locations, dim=2)
        return list(locations.unbind(0))


@contextlib.contextmanager
def _torch_threads(num_threads: int | None) -> Iterator[None]:
    """Run the body with ``torch.set_num_threads(num_threads)`` (None: leave it alone)."""
    if num_threads is None:
        yield
        return
    if num_threads < 1:
        raise ValueError(f"num_threads must be >= 1 or None, got {num_threads}")
    previous = torch.get_num_threads()
    torch.set_num_threads(num_threads)
    try:
        yield
    finally:
        torch.set_num_threads(previous)
