"""The UniTrack association head (agent ``unitrack``): boxes, masks and poses with one agent.

One agent plays every association environment -- MOT (boxes), MOTS (masks), VIS (masks
with classes) and PoseTrack (poses) -- and tells them apart by the observation's keys
(``keypoints``: poses; ``masks``: masks, with ``classes``: VIS; else boxes), or by the
``task`` option. Per frame (UniTrack paper, section 2.4 and appendix C; facts about the
authors' code in ``OFFICIAL-CODE-FACTS.md``, "Association"):

1. Read the frame's observations and drop unusable ones (score below ``min_score``, empty
   boxes or masks, poses without a visible keypoint).
2. Turn every observation into a box for the Kalman filter and the IoU stages and a region
   for appearance: a box is itself; a mask gives the paper's mean / mean-absolute-deviation
   box (appendix C.1, :func:`~unitrack_env.agents.primitives.mask_features.mask_to_box`); a pose is
   first drawn as a mask (appendix C.2,
   :func:`~unitrack_env.agents.primitives.mask_features.pose_to_mask`).
3. Letterbox the frame to ``input_size`` (default 1088 x 608) and run the appearance model
   once: a stride-8 feature map (frames without observations skip it).
4. Object features: a box is RoIAlign-pooled into a tall 10 x 4 grid (40 locations); a mask
   (or drawn pose) gives its in-mask feature cells, a variable-size set capped at
   ``max_mask_area`` locations by rescaling (authors: 200 MOTS, 1000 VIS); every location
   is L2-normalised.
5. Associate with :class:`~unitrack_env.agents.primitives.association.Associator` (appearance
   similarity,
   RSM by default, fused with Kalman motion; then IoU; track life cycle). On VIS each class
   has its own engine
   (:class:`~unitrack_env.agents.primitives.category_gating.CategoryGatedAssociator`):
   a track only matches detections of its class.
6. Act in the environment's format: MOT boxes of the confirmed tracks matched in the frame;
   MOTS/VIS one id per detection (0 = not reported); PoseTrack the ids with the matched
   poses echoed.

Task defaults (:data:`TASK_DEFAULTS`) follow the authors' per-task settings; where their code
passes a threshold as an IoU *distance* (``1 - IoU``), it is converted to an IoU here (the
MOT values are explained in :class:`~unitrack_env.agents.primitives.association.AssociationConfig`):

* ``mot``: chi-square gate 9.4877; duplicates at IoU > 0.85 (code: 0.15 distance); MOT
  output filter; plus four measured departures from the paper
  (:data:`~unitrack_env.agents.primitives.association.MOT_ASSOCIATION`: detection boxes
  reported, an ambiguity margin of 0.1 on appearance matches, confirmation at IoU > 0.5
  instead of 0.8, lost tracks in the IoU stage); ``paper_settings=True`` drops them.
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

Example:
    >>> import gymnasium as gym, unitrack_env                    # doctest: +SKIP
    >>> from unitrack_env.agents import make_agent                             # doctest: +SKIP
    >>> env = gym.make("UniTrack/MOTS-v0")                        # doctest: +SKIP
    >>> agent = make_agent("unitrack")                            # doctest: +SKIP
    >>> obs, info = env.reset(); agent.reset(obs, info)           # doctest: +SKIP
    >>> obs, reward, terminated, truncated, info = env.step(agent.act(obs))  # doctest: +SKIP
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from unitrack_env.agents.appearance import (
    MOT_INPUT_SIZE,
    AppearanceModel,
    CachedAppearanceModel,
    Letterbox,
    content_key,
    letterbox,
    letterbox_layout,
    resolve_cache,
    torch_threads,
)
from unitrack_env.agents.appearance.model import LETTERBOX_PAD_VALUE
from unitrack_env.agents.base import Agent
from unitrack_env.agents.primitives.association import (
    MOT_ASSOCIATION,
    AssociationConfig,
    Associator,
    TrackOutput,
)
from unitrack_env.agents.primitives.category_gating import CategoryGatedAssociator
from unitrack_env.agents.primitives.mask_features import (
    MAX_MASK_AREA_MOTS,
    MAX_MASK_AREA_VIS,
    LocalMask,
    mask_location_features,
    mask_to_box,
    pose_to_mask,
)
from unitrack_env.agents.primitives.roi_align import roi_align
from unitrack_env.agents.primitives.similarity import SIMILARITIES, ObjectFeatures
from unitrack_env.geometry import xywh_to_xyxy
from unitrack_env.spaces import (
    pack_mask_ids,
    pack_pose_tracks,
    pack_tracks,
    unpack_detections,
    unpack_poses,
)

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
"""Default action capacity of box tasks (the MOTChallenge environments' ``max_tracks``)."""

POSETRACK_MAX_TRACKS: int = 100
"""Default action capacity of pose tracking (the PoseTrack environment's ``max_tracks``)."""

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
        max_tracks: Default action capacity (pose tracks; box tracks).
    """

    observation: str
    association: Mapping[str, Any] = field(default_factory=dict)
    output_filter: bool = False
    max_mask_area: int | None = None
    category_gating: bool = False
    max_tracks: int = DEFAULT_MAX_TRACKS


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
    "posetrack": TaskDefaults("poses", _POSE_VIS_ASSOCIATION, max_mask_area=MAX_MASK_AREA_MOTS,
                              max_tracks=POSETRACK_MAX_TRACKS),
})
"""Task name -> :class:`TaskDefaults` (read-only)."""


def detect_task(observation: Mapping[str, Any]) -> str:
    """The association task an observation belongs to, from its keys.

    ``keypoints`` -> ``"posetrack"``; ``masks`` with ``classes`` -> ``"vis"``; ``masks`` ->
    ``"mots"``; ``boxes`` -> ``"mot"``.

    Raises:
        ValueError: None of these keys.

    >>> detect_task({"frame": None, "masks": None, "classes": None})
    'vis'
    """
    if not isinstance(observation, Mapping):
        raise ValueError(f"expected a dict observation, got {type(observation).__name__}")
    if "keypoints" in observation:
        return "posetrack"
    if "masks" in observation:
        return "vis" if "classes" in observation else "mots"
    if "boxes" in observation:
        return "mot"
    raise ValueError(
        f"cannot tell the association task from the observation keys {sorted(observation)}; "
        "expected 'boxes' (MOT), 'masks' (MOTS; with 'classes': VIS) or 'keypoints' "
        "(PoseTrack), or pass task= to the agent"
    )


@dataclass(frozen=True)
class UniTrackConfig:
    """Options of the ``unitrack`` agent.

    Attributes:
        task: ``"mot"``, ``"mots"``, ``"vis"`` or ``"posetrack"``; None: detect it from the
            first observation (see :func:`detect_task`). Selects :data:`TASK_DEFAULTS`.
        weights: Appearance-model weights (see
        :class:`~unitrack_env.agents.appearance.AppearanceModel`):
            ``"imagenet-lite0"`` (default, offline), ``"random"``, a checkpoint path, ...
        arch: Backbone architecture; None: the weights' own.
        layer: Output layer; None: the architecture's default stride-8 layer.
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
        device: Torch device of the appearance model.
        num_threads: Torch threads while the agent acts (backbone and similarity; restored
            afterwards). None: torch's current setting. 1 is much faster when several
            processes share the cores (thread oversubscription).
        paper_settings: Reproduce the paper's association setting exactly (the authors' code
            where the paper gives no value): the task defaults' measured departures
            (:data:`~unitrack_env.agents.primitives.association.MOT_ASSOCIATION`) are not
            applied. Explicit ``association`` fields still override.
        association: Any other :class:`AssociationConfig` fields (thresholds, lambda, ...);
            they override the task's defaults.
    """

    task: str | None = None
    weights: str = "imagenet-lite0"
    arch: str | None = None
    layer: str | None = None
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
    device: str = "cpu"
    num_threads: int | None = None
    paper_settings: bool = False
    association: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.task is not None and self.task not in TASK_DEFAULTS:
            raise ValueError(f"unknown task {self.task!r}; valid tasks: {', '.join(TASKS)}")
        if self.mask_box not in MASK_BOX_MODES:
            raise ValueError(
                f"mask_box must be one of {', '.join(MASK_BOX_MODES)}, got {self.mask_box!r}")
        if self.max_mask_area is not None and self.max_mask_area < 1:
            raise ValueError(f"max_mask_area must be >= 1 or None, got {self.max_mask_area}")

    def defaults(self, task: str) -> TaskDefaults:
        """The :class:`TaskDefaults` of ``task``."""
        try:
            return TASK_DEFAULTS[task]
        except KeyError:
            raise ValueError(f"unknown task {task!r}; valid tasks: {', '.join(TASKS)}") from None

    def output_filter_for(self, task: str) -> bool:
        """Whether the MOT output filter applies on ``task``."""
        return self.defaults(task).output_filter if self.output_filter is None \
            else self.output_filter

    def max_mask_area_for(self, task: str) -> int | None:
        """The mask-area cap on ``task``."""
        return self.max_mask_area if self.max_mask_area is not None \
            else self.defaults(task).max_mask_area

    def category_gating_for(self, task: str) -> bool:
        """Whether tracks are gated by class on ``task``."""
        return self.defaults(task).category_gating if self.category_gating is None \
            else self.category_gating

    def association_config(self, task: str = "mot") -> AssociationConfig:
        """The :class:`AssociationConfig` these options describe on ``task``."""
        output_filter = self.output_filter_for(task)
        base = AssociationConfig(
            use_motion=self.use_motion,
            new_track_score=self.new_track_score,
            output_min_area=MOT_OUTPUT_MIN_AREA if output_filter else None,
            output_max_aspect=MOT_OUTPUT_MAX_ASPECT if output_filter else None,
        )
        try:
            defaults = dict(self.defaults(task).association)
            if self.paper_settings and task == "mot":
                defaults = {}
            return replace(base, **{**defaults, **self.association})
        except TypeError as exc:
            valid = ", ".join(sorted(AssociationConfig.__dataclass_fields__))
            raise TypeError(f"bad association option ({exc}); valid fields: {valid}") from None


@dataclass(frozen=True)
class _Parsed:
    """One frame's usable observations, ready for association.

    Attributes:
        index: Position of each kept observation in the frame's observation.
        boxes: ``(m, 4)`` Kalman boxes ``(x, y, w, h)``.
        scores: ``(m,)`` scores.
        masks: The kept masks (masks and poses) or None (boxes).
        categories: ``(m,)`` classes when gating by class, else None.
    """

    index: np.ndarray
    boxes: np.ndarray
    scores: np.ndarray
    masks: list[LocalMask] | None = None
    categories: np.ndarray | None = None


class UniTrackAgent(Agent, name="unitrack", tasks=TASKS):
    """UniTrack's association head for boxes, masks and poses (MOT, MOTS, VIS, PoseTrack).

    Args:
        max_tracks: Action capacity of box and pose tasks; must equal the environment's
            ``max_tracks``. None: the task's default (512 MOT, 100 PoseTrack, the
            environments' defaults). Mask tasks answer one id per detection instead.
        appearance_model: A ready :class:`~unitrack_env.agents.appearance.AppearanceModel` to share
        between agents (then ``weights``/``arch``/``layer``/``device``/``num_threads`` are
            ignored).
        **options: Fields of :class:`UniTrackConfig`.

    Attributes:
        config: The options.
        task: The task being played (from ``config.task``, else the latest observation;
            ``"mot"`` until an observation says otherwise).
        model: The appearance model (possibly wrapped by the feature cache).
        associator: The association engine of the task (its state is the agent's episode
            state); a :class:`CategoryGatedAssociator` when tracks are gated by class.
    """

    config_class = UniTrackConfig

    def __init__(
        self,
        max_tracks: int | None = None,
        *,
        appearance_model: AppearanceModel | None = None,
        **options: Any,
    ) -> None:
        try:
            self.config = UniTrackConfig(**options)
        except TypeError as exc:
            valid = ", ".join(sorted(UniTrackConfig.__dataclass_fields__))
            raise TypeError(f"unitrack: {exc}; valid options: {valid}") from None
        cfg = self.config
        for task in TASKS:  # fail now, not at the first observation, on a bad option
            cfg.association_config(task)
        self._max_tracks = None if max_tracks is None else int(max_tracks)
        if callable(cfg.similarity):
            self._similarity: Callable[..., Any] = cfg.similarity
        else:
            self._similarity = SIMILARITIES[cfg.similarity]
        base = appearance_model or AppearanceModel(
            cfg.weights, arch=cfg.arch, layer=cfg.layer, device=cfg.device,
            num_threads=cfg.num_threads,
        )
        self.appearance = base
        # (an injected model without an identity cannot be keyed: it runs uncached)
        cache = resolve_cache(cfg.feature_cache, max_size=cfg.feature_cache_size) \
            if hasattr(base, "identity") else None
        self.model: AppearanceModel | CachedAppearanceModel = (
            CachedAppearanceModel(base, cache) if cache is not None else base
        )
        self.task = cfg.task or "mot"
        self.associator: Associator[Any] | CategoryGatedAssociator[Any] = self._engine(self.task)
        self._sequence = ""
        self._frame_index = 0

    @property
    def max_tracks(self) -> int:
        """Action capacity of box and pose tracks on the current task."""
        return self._max_tracks if self._max_tracks is not None \
            else self.config.defaults(self.task).max_tracks

    def _engine(
        self, task: str, frame_rate: float = 30.0
    ) -> Associator[Any] | CategoryGatedAssociator[Any]:
        config = self.config.association_config(task)
        if self.config.category_gating_for(task):
            return CategoryGatedAssociator(self._similarity, config, frame_rate)
        return Associator(self._similarity, config, frame_rate)

    def _use_task(self, observation: Any, *, new_episode: bool = False) -> str:
        """Switch to the observation's task (rebuilding the engine) when not fixed by config."""
        if self.config.task is not None or observation is None:
            return self.task
        task = detect_task(observation)
        if task != self.task:
            engine = self.associator
            started = engine.frame_index > 0 if isinstance(engine, Associator) \
                else bool(engine.categories)
            if started and not new_episode:
                raise ValueError(
                    f"the observation format changed from {self.task} to {task} in the middle "
                    "of an episode; call reset() with the new environment's first observation"
                )
            self.task = task
            self.associator = self._engine(task, engine.frame_rate)
        return self.task

    # ------------------------------------------------------------------ episode
    def reset(self, observation: Any, info: dict[str, Any]) -> None:
        """Forget all tracks and ids; read ``frame_rate`` (and the sequence name) from info.

        The observation (may be None) tells the task when ``task`` is not set.
        """
        self._use_task(observation, new_episode=True)
        frame_rate = info.get("frame_rate")
        self.associator.reset(frame_rate=float(frame_rate) if frame_rate else None)
        self._sequence = str(info.get("sequence", ""))
        # act() numbers frames from the reset frame (the benchmark's index, usually 1).
        self._frame_index = int(info.get("frame_index", 1)) - 1
        if isinstance(self.model, CachedAppearanceModel):
            self.model.flush_stats()  # the previous episodes' hit counts, for `unitrack cache`

    def close(self) -> None:
        """Record the feature cache's hit counts (read by ``unitrack cache info``)."""
        if isinstance(self.model, CachedAppearanceModel):
            self.model.flush_stats()

    def act(self, observation: dict[str, Any]) -> dict[str, Any]:
        """Track one frame; return the action in the environment's format."""
        with torch_threads(self.config.num_threads):
            task = self._use_task(observation)
            self._frame_index += 1
            if task == "mot":
                return self._act_boxes(observation)
            if task == "posetrack":
                return self._act_poses(observation)
            return self._act_masks(observation)

    def _step(self, parsed: _Parsed, features: Sequence[Any]) -> list[TrackOutput]:
        if isinstance(self.associator, CategoryGatedAssociator):
            categories = parsed.categories if parsed.categories is not None \
                else np.zeros(len(parsed.boxes), dtype=np.int64)
            return self.associator.step(parsed.boxes, parsed.scores, features, categories)
        return self.associator.step(parsed.boxes, parsed.scores, features)

    # ------------------------------------------------------------------ boxes (MOT)
    def _act_boxes(self, observation: dict[str, Any]) -> dict[str, Any]:
        boxes, scores = unpack_detections(observation)
        boxes = np.asarray(boxes, dtype=np.float64)
        scores = np.asarray(scores, dtype=np.float64)
        keep = np.all(np.isfinite(boxes), axis=1) & (boxes[:, 2] > 0) & (boxes[:, 3] > 0)
        keep &= np.isfinite(scores)
        if self.config.min_score is not None:
            keep &= scores >= self.config.min_score
        parsed = _Parsed(np.flatnonzero(keep), boxes[keep], scores[keep])
        payloads = self.box_features(observation["frame"], parsed.boxes) if len(parsed.boxes) \
            else []
        outputs = self._step(parsed, payloads)
        return pack_tracks(
            [o.track_id for o in outputs],
            np.array([o.box for o in outputs]).reshape(-1, 4),
            self.max_tracks,
        )

    # ------------------------------------------------------------------ masks (MOTS, VIS)
    def _act_masks(self, observation: dict[str, Any]) -> dict[str, Any]:
        n = int(observation["num_detections"])
        capacity = len(observation["scores"])
        scores = np.asarray(observation["scores"][:n], dtype=np.float64)
        masks = [LocalMask.from_full(m) for m in np.asarray(observation["masks"][:n])]
        classes = observation.get("classes")
        keep = np.array([m.area > 0 for m in masks], dtype=bool).reshape(-1)
        keep &= np.isfinite(scores)
        if self.config.min_score is not None:
            keep &= scores >= self.config.min_score
        parsed = self._parse_masks(np.flatnonzero(keep), masks, scores,
                                   None if classes is None else np.asarray(classes[:n]))
        outputs = self._step(parsed, self._region_features(observation["frame"], parsed))
        ids = np.zeros(n, dtype=np.int64)
        for out in outputs:
            ids[parsed.index[out.detection_index]] = out.track_id
        return pack_mask_ids(ids, capacity)

    def _parse_masks(self, index: np.ndarray, masks: Sequence[LocalMask], scores: np.ndarray,
                     classes: np.ndarray | None) -> _Parsed:
        kept = [masks[i] for i in index]
        if self.config.mask_box == "mad":
            boxes = [mask_to_box(m) for m in kept]
        else:
            boxes = [m.tight_box() for m in kept]
        categories = None
        if classes is not None and self.config.category_gating_for(self.task):
            categories = np.asarray(classes, dtype=np.int64)[index]
        return _Parsed(index, np.array(boxes, dtype=np.float64).reshape(-1, 4), scores[index],
                       kept, categories)

    # ------------------------------------------------------------------ poses (PoseTrack)
    def _act_poses(self, observation: dict[str, Any]) -> dict[str, Any]:
        keypoints, scores = unpack_poses(observation)
        keypoints = np.asarray(keypoints, dtype=np.float64)
        scores = np.asarray(scores, dtype=np.float64)
        masks: list[LocalMask] = []
        keep = np.isfinite(scores) & np.all(np.isfinite(keypoints), axis=(1, 2))
        if self.config.min_score is not None:
            keep &= scores >= self.config.min_score
        for i in range(len(keypoints)):
            mask = pose_to_mask(keypoints[i], min_score=self.config.min_keypoint_score) \
                if keep[i] else None
            masks.append(mask if mask is not None else LocalMask(np.zeros((0, 0), bool)))
            keep[i] = mask is not None
        parsed = self._parse_masks(np.flatnonzero(keep), masks, scores, None)
        outputs = self._step(parsed, self._region_features(observation["frame"], parsed))
        rows = np.array([parsed.index[o.detection_index] for o in outputs], dtype=np.int64)
        observed = np.asarray(observation["keypoints"], dtype=np.float32)[: len(keypoints)]
        return pack_pose_tracks([o.track_id for o in outputs], observed[rows], self.max_tracks)

    # ------------------------------------------------------------------ features
    def feature_map(self, frame: np.ndarray) -> tuple[torch.Tensor, Letterbox]:
        """Letterbox ``frame`` and return its ``(1, C, h, w)`` feature map and the letterbox.

        With the feature cache, entries are keyed by a hash of the original frame (and the
        letterbox), so a hit needs only the letterbox geometry (no resize).
        """
        size = tuple(self.config.input_size)
        if not isinstance(self.model, CachedAppearanceModel):
            boxed = letterbox(np.ascontiguousarray(frame), size)
            return self.model.features(boxed.image), boxed
        key = content_key(frame, f"letterbox {size[0]}x{size[1]} pad {LETTERBOX_PAD_VALUE}")
        fmap = self.model.lookup((size[1], size[0]), key)
        if fmap is not None:
            return fmap, letterbox_layout(frame.shape[0], frame.shape[1], size)
        boxed = letterbox(np.ascontiguousarray(frame), size)
        return self.model.features(boxed.image, keys=[key]), boxed

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

    def mask_features(self, frame: np.ndarray, masks: Sequence[LocalMask]) -> list[ObjectFeatures]:
        """In-mask location features of each (non-empty) mask of one frame.

        Args:
            frame: uint8 RGB ``(H, W, 3)`` frame.
            masks: Masks in the frame's pixels (drawn poses included).

        Returns:
            One ``ObjectFeatures`` per mask: ``(s_i, C)`` L2-normalised features, at most
            the task's ``max_mask_area`` of them, with their feature-cell positions.
        """
        fmap, boxed = self.feature_map(frame)
        stride = self.appearance.stride
        return mask_location_features(
            fmap, masks, lambda b: boxed.boxes_to_features(b, stride),
            max_area=self.config.max_mask_area_for(self.task),
            sampling_ratio=self.config.roi_sampling_ratio,
        )

    def _region_features(self, frame: np.ndarray, parsed: _Parsed) -> list[ObjectFeatures]:
        if not parsed.masks:
            return []
        return self.mask_features(frame, parsed.masks)
