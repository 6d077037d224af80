"""Object features of one frame for the ``unitrack`` association agent.

One appearance-model pass on the letterboxed frame; a box is RoIAlign-pooled into a
``roi_size`` grid, a mask (or drawn pose) gives its in-mask cells capped at ``max_area``.
Every location feature is L2-normalised.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
import torch.nn.functional as F

from unitrack_env.geometry import xywh_to_xyxy

from ..appearance.cache_keys import content_key
from ..appearance.cached_model import CachedAppearanceModel
from ..appearance.letterboxing import (
    LETTERBOX_PAD_VALUE,
    Letterbox,
    letterbox,
    letterbox_layout,
)
from ..appearance.model import AppearanceModel
from ..primitives.mask_features import LocalMask, mask_location_features
from ..primitives.roi_align import roi_align
from ..primitives.similarity import ObjectFeatures


class RegionFeatures:
    """Box and mask features of a frame from one (possibly cached) appearance model."""

    def __init__(self, model: AppearanceModel | CachedAppearanceModel, stride: int, *,
                 input_size: tuple[int, int], roi_size: tuple[int, int], sampling_ratio: int,
                 pixel_origin: float) -> None:
        self.model = model
        self.stride = stride
        self.input_size = tuple(input_size)
        self.roi_size = tuple(roi_size)
        self.sampling_ratio = sampling_ratio
        self.pixel_origin = pixel_origin

    def feature_map(self, frame: np.ndarray) -> tuple[torch.Tensor, Letterbox]:
        """Letterbox ``frame``; return its ``(1, C, h, w)`` feature map and the letterbox.

        Cache entries are keyed by the original frame, so a hit skips the resize.
        """
        size = self.input_size
        if not isinstance(self.model, CachedAppearanceModel):
            boxed = letterbox(np.ascontiguousarray(frame), size)
            return self.model.features(boxed.image), boxed
        key = content_key(frame, f"letterbox {size[0]}x{size[1]} pad {LETTERBOX_PAD_VALUE}")
        fmap = self.model.lookup((size[1], size[0]), key)
        if fmap is not None:
            return fmap, letterbox_layout(frame.shape[0], frame.shape[1], size)
        boxed = letterbox(np.ascontiguousarray(frame), size)
        return self.model.features(boxed.image, keys=[key]), boxed

    def boxes(self, frame: np.ndarray, boxes_xywh: np.ndarray) -> list[torch.Tensor]:
        """L2-normalised ``(rows * cols, C)`` location features of each ``(n, 4)`` box."""
        fmap, boxed = self.feature_map(frame)
        xyxy = xywh_to_xyxy(boxes_xywh) - self.pixel_origin
        rois = torch.as_tensor(boxed.boxes_to_features(xyxy, self.stride), dtype=fmap.dtype)
        pooled = roi_align(
            fmap, rois, self.roi_size, spatial_scale=1.0, sampling_ratio=self.sampling_ratio,
        )  # (n, C, rows, cols)
        locations = pooled.flatten(2).transpose(1, 2)  # (n, rows * cols, C), row-major
        locations = F.normalize(locations, dim=2)
        return list(locations.unbind(0))

    def masks(self, frame: np.ndarray, masks: Sequence[LocalMask],
              max_area: int | None) -> list[ObjectFeatures]:
        """In-mask ``ObjectFeatures`` of each non-empty mask (at most ``max_area`` cells)."""
        fmap, boxed = self.feature_map(frame)
        stride = self.stride
        return mask_location_features(
            fmap, masks, lambda b: boxed.boxes_to_features(b, stride),
            max_area=max_area, sampling_ratio=self.sampling_ratio,
        )
