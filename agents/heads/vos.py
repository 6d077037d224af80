"""The UniTrack VOS head: mask propagation with the shared appearance model (``unitrack-vos``).

Per video (paper section 2.3, appendix B.2; ``OFFICIAL-CODE-FACTS.md``, "Mask and pose
propagation"): at reset the first frame's labels (0 background, ``k`` object ``k``, 255 void,
counted as background) become one-hot channels downsampled bilinearly to the feature grid;
they and the first frame's features start the memory bank of
:class:`~unitrack_env.agents.primitives.label_propagation.LabelPropagator`. The first step
answers the first frame with the given labels. Every later frame: one backbone pass at full
resolution, propagation of the soft labels (first frame + 5 latest, radius 12 cells at
stride 8, i.e. 96 pixels at any stride, top-10, temperature 0.05), bilinear upsampling to
the frame, argmax. The propagation's options are flat fields of
:class:`PropagationHeadConfig` (shared with ``unitrack-pose``), among them
``propagation_precision="bf16"``: measured the same J&F and PCK on the fixtures, refused
before the first frame on a CPU without native bfloat16 (docs/design-decisions.md, "Label
propagation: precision").
"""

from __future__ import annotations

import os
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from ..appearance.cached_model import with_cache
from ..appearance.model import AppearanceModel, torch_threads
from ..appearance.spec import AppearanceSpec
from ..base import Agent
from ..primitives.label_propagation import LabelPropagationConfig, LabelPropagator

VOID_LABEL: int = 255
"""DAVIS's void label (ambiguous pixels of the annotation); treated as background."""


@dataclass(frozen=True)
class PropagationHeadConfig(AppearanceSpec, LabelPropagationConfig):
    """Options of a label-propagation head, flat: ``name = default`` [paper value].

    Appearance: weights, arch, layer, remap, device, runtime, stride, num_threads
    (:class:`AppearanceSpec`). Propagation (:class:`LabelPropagationConfig`, table B.2):
    ``memory_size = 6`` [first frame + 5], ``radius = 12.0`` [12 cells at stride 8],
    ``first_frame_radius = None`` [no limit], ``radius_stride = 8``, ``topk = 10`` [10],
    ``temperature = 0.05`` [0.05], ``normalize = True`` [cosine], ``tile_size = 8``,
    ``max_affinity_elements`` (speed and memory only), ``propagation_precision =
    "float32"`` [exact] or ``"bf16"``. ``feature_cache = True``: the on-disk feature cache
    (the default folder; a folder; False), float32 entries, read instead of computed.
    """

    feature_cache: str | os.PathLike[str] | bool | None = True

    def propagation_config(self, stride: int | None = None) -> LabelPropagationConfig:
        """The propagator's :class:`LabelPropagationConfig`, radii rescaled to ``stride``."""
        config = LabelPropagationConfig(**{f.name: getattr(self, f.name)
                                           for f in fields(LabelPropagationConfig)})
        return config if stride is None else config.for_stride(stride)


@dataclass(frozen=True)
class UniTrackVOSConfig(PropagationHeadConfig):
    """Options of ``unitrack-vos``: :class:`PropagationHeadConfig`'s and ``antialias``.

    ``antialias = True``: antialias the downsampling of the first frame's labels to the
    feature grid.
    """

    antialias: bool = True


def build_model(config: AppearanceSpec, model: AppearanceModel | None) -> AppearanceModel:
    """The shared model if given, else the one ``config``'s appearance fields name."""
    return model if model is not None else config.build()


def labels_to_onehot(labels: np.ndarray, object_ids: tuple[int, ...]) -> torch.Tensor:
    """``(1 + n, H, W)`` float one-hot ``[background, object_ids...]``; void is background."""
    lab = torch.from_numpy(np.ascontiguousarray(labels).astype(np.int64))
    channels = [torch.ones_like(lab, dtype=torch.float32)]
    for obj in object_ids:
        channels.append((lab == obj).float())
    onehot = torch.stack(channels)
    onehot[0] = 1.0 - onehot[1:].sum(0).clamp(max=1.0)
    return onehot


class UniTrackVOSAgent(Agent, name="unitrack-vos", tasks=("vos",)):
    """UniTrack's mask-propagation head for semi-supervised VOS (DAVIS).

    ``appearance_model``: a ready model to share (the appearance options are then ignored);
    ``**options``: :class:`UniTrackVOSConfig` fields. Channel ``i + 1`` of the propagated labels
    is object ``object_ids[i]``.
    """

    config_class = UniTrackVOSConfig

    def __init__(self, *, appearance_model: AppearanceModel | None = None,
                 **options: Any) -> None:
        self.config, self.model = UniTrackVOSConfig.configure(self.name, options, appearance_model)
        self.cached = with_cache(self.model, self.config.feature_cache)
        self.propagator = LabelPropagator(self.config.propagation_config(self.model.stride))
        self.object_ids: tuple[int, ...] = ()
        self._first_answer: np.ndarray | None = None
        self._lookup = np.zeros(1, np.uint8)
        self._size = (0, 0)

    def reset(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        """Read the first frame's labels; compute its features; start the memory bank."""
        labels = np.asarray(observation["init_labels"])
        ids = sorted(int(v) for v in np.unique(labels) if v not in (0, VOID_LABEL))
        self.object_ids = tuple(ids)
        self._lookup = np.array([0, *ids], dtype=np.uint8)
        answer = labels.astype(np.uint8, copy=True)
        answer[answer == VOID_LABEL] = 0
        self._first_answer = answer
        frame = observation["frame"]
        self._size = labels.shape[:2]
        if frame.shape[:2] != self._size:
            raise ValueError(
                f"frame {frame.shape[:2]} and init_labels {self._size} differ in size; "
                "unitrack-vos needs the decoded frames (decode_frames=True)"
            )
        with torch_threads(self.config.num_threads):
            features = self.cached.features(frame)[0]
            onehot = labels_to_onehot(labels, self.object_ids).to(features.device)
            small = F.interpolate(self._grid_canvas(onehot)[None],
                                  size=features.shape[1:], mode="bilinear",
                                  align_corners=False, antialias=self.config.antialias)[0]
            self.propagator.reset(features, small)

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        """The label map ``(H, W)`` uint8 of the current frame."""
        if self._first_answer is not None:  # the first step answers the reset frame
            answer, self._first_answer = self._first_answer, None
            return answer
        if self.propagator.memory_length == 0:
            raise RuntimeError("call reset() with the first observation before act()")
        with torch_threads(self.config.num_threads), torch.inference_mode():
            features = self.cached.features(observation["frame"])[0]
            soft = self.propagator.step(features)
            return self.decode(soft)

    def _grid_canvas(self, onehot: torch.Tensor) -> torch.Tensor:
        """``onehot`` padded (background) to the pixels the feature map spans.

        A ViT's cell ``j`` covers pixels ``[s j, s j + s)``: resizing the frame's own extent
        to its grid would shift the bottom rows by up to a cell when ``s`` does not divide
        the frame (14 on 480 rows). A CNN's map spans the frame (no padding).
        """
        rows, cols = self.model.map_extent(*onehot.shape[1:])
        pad_h, pad_w = rows - onehot.shape[1], cols - onehot.shape[2]
        if pad_h <= 0 and pad_w <= 0:
            return onehot
        canvas = F.pad(onehot, (0, max(pad_w, 0), 0, max(pad_h, 0)))
        canvas[0] = 1.0 - canvas[1:].sum(0).clamp(max=1.0)
        return canvas

    def decode(self, soft: torch.Tensor) -> np.ndarray:
        """Soft labels ``(1 + n, h, w)`` -> ``(H, W)`` uint8 object labels (bilinear + argmax)."""
        height, width = self._size
        rows, cols = self.model.map_extent(height, width)
        full = F.interpolate(soft[None], size=(max(rows, height), max(cols, width)),
                             mode="bilinear", align_corners=False)[0, :, :height, :width]
        # max(0).indices: the first maximal channel, as argmax(0), but a reduction over the
        # leading dim that runs 30-60x faster on CPU (480p: ~1 ms vs ~31 ms per frame).
        channel = full.max(0).indices.numpy().astype(np.intp)
        return self._lookup[channel]
