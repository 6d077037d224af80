"""The UniTrack point tracking head (``unitrack-points``): points as propagated belief maps.

The pose-propagation head of the UniTrack paper (section 2.3, appendix B.2) applied to any
point: a query becomes a Gaussian belief map on the appearance model's feature grid at its
query frame; the paper's label propagation (memory of the query frame and the latest
frames, local radius, top-k, temperature; :class:`LabelPropagator`) carries it frame to
frame; the peak, refined by a soft-argmax around it, is the position, and the share of the
query frame's peak that survives is the propagation's confidence, which decides occlusion.
Queries revealed at the same frame share one propagator (one memory bank per query frame).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import torch

from ..appearance.cached_model import with_cache
from ..appearance.model import AppearanceModel, torch_threads
from ..base import Agent
from ..primitives.label_propagation import LabelPropagator
from ..primitives.point_queries import QueryBook
from .pose import MIN_PEAK, MIN_SIGMA, REFINE_RADIUS, belief_maps, decode_maps
from .vos import PropagationHeadConfig

SIGMA: float = MIN_SIGMA
"""Gaussian sigma of a point's belief map, in feature cells: the paper's floor
``sigma = max(eta s_body, 0.5)`` for the smallest body, which a single point is."""

OCCLUSION_RATIO: float = 0.2
"""A point is reported occluded when its map's peak falls below this share of its peak at
the query frame. The rule: flag about one visible point in ten. Measured over the six clips
at hand (the three synthetic TAPVid-DAVIS videos and the three real fixtures, forward
propagation), the ratio of visible points has its 10th percentile at 0.13 and 0.20 and its
median at 0.45 and 0.56; that of occluded points its median at 0.18 and 0.14
(docs/design-decisions.md, "Point head"). Not tuned for a score."""


@dataclass(frozen=True)
class UniTrackPointsConfig(PropagationHeadConfig):
    """Options of ``unitrack-points``: :class:`PropagationHeadConfig`'s and the head's own.

    From :class:`PropagationHeadConfig`: appearance, flat propagation fields, feature cache.

    Attributes:
        input_size: ``(width, height)`` frames are resized to (None: the raster as given).
        sigma: Belief map sigma (feature cells).
        refine_radius: Soft-argmax neighbourhood half-side (feature cells; 0: argmax).
        occlusion_ratio: Peak share under which a point is reported occluded.
    """

    input_size: tuple[int, int] | None = None
    sigma: float = SIGMA
    refine_radius: int = REFINE_RADIUS
    occlusion_ratio: float = OCCLUSION_RATIO


class _Group:
    """The queries revealed at one frame: their propagator and their query-frame peaks."""

    def __init__(self, ids: np.ndarray, propagator: LabelPropagator, peaks: np.ndarray) -> None:
        self.ids, self.propagator, self.peaks = ids, propagator, peaks


class UniTrackPointsAgent(Agent, name="unitrack-points", tasks=("points",)):
    """UniTrack's propagation head for points; ``appearance_model``: a shared model."""

    config_class = UniTrackPointsConfig

    def __init__(self, *, appearance_model: AppearanceModel | None = None,
                 **options: Any) -> None:
        self.config, self.model = UniTrackPointsConfig.configure(self.name, options,
                                                                 appearance_model)
        self.propagation = self.config.propagation_config(self.model.stride)
        self.cached = with_cache(self.model, self.config.feature_cache)
        self.book = QueryBook()
        self._groups: list[_Group] = []
        self._scale = np.ones(2)  # feature cells per raster pixel (x, y)
        #: Per query id, its last peak as a share of its query-frame peak (the confidence
        #: occlusion is decided from; 1 at the query frame).
        self.confidence = np.zeros(0)

    def _features(self, frame: np.ndarray) -> torch.Tensor:
        raster_height, raster_width = frame.shape[:2]
        width, height = self.config.input_size or (raster_width, raster_height)
        if (raster_width, raster_height) != (width, height):
            frame = cv2.resize(np.ascontiguousarray(frame), (width, height),
                               interpolation=cv2.INTER_LINEAR)
        features = self.cached.features(frame)[0]
        rows, cols = self.model.map_extent(height, width)  # input pixels the map spans
        self._scale = np.array([features.shape[2] / (cols * raster_width / width),
                                features.shape[1] / (rows * raster_height / height)])
        return features

    def _to_grid(self, points: np.ndarray) -> np.ndarray:
        """Raster points (pixel centres at ``i + 0.5``) in feature cells (centres at ``j``)."""
        return np.asarray(points, np.float64) * self._scale - 0.5

    def _to_raster(self, cells: np.ndarray) -> np.ndarray:
        return (np.asarray(cells, np.float64) + 0.5) / self._scale

    def reset(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        """Start an episode (queries arrive with the observations)."""
        self.book.reset(info)
        self._groups = []
        self.confidence = np.ones(self.book.capacity)

    def _start_group(self, ids: np.ndarray, features: torch.Tensor) -> None:
        shape = (features.shape[1], features.shape[2])
        maps = belief_maps(self._to_grid(self.book.positions[ids]), shape, self.config.sigma)
        propagator = LabelPropagator(self.propagation)
        propagator.reset(features, maps.to(features.device))
        peaks = maps.reshape(len(ids), -1).max(dim=1).values.double().numpy()
        self._groups.append(_Group(ids, propagator, peaks))

    def act(self, observation: dict[str, Any]) -> dict[str, np.ndarray]:
        """Propagate every group to this frame, then start the group of the new queries."""
        new, restarted = self.book.update(observation)
        if restarted:
            self._groups = []
        with torch_threads(self.config.num_threads), torch.inference_mode():
            features = self._features(observation["frame"])
            for group in self._groups:
                maps = group.propagator.step(features)
                cells, peaks = decode_maps(maps.cpu(), self.config.refine_radius)
                kept = peaks > MIN_PEAK  # else the map is empty: stay where it was
                self.book.positions[group.ids[kept]] = self._to_raster(cells[kept])
                self.confidence[group.ids] = np.divide(
                    np.where(kept, peaks, 0.0), group.peaks, out=np.zeros(len(peaks)),
                    where=group.peaks > 0)
                self.book.occluded[group.ids] = (self.confidence[group.ids]
                                                 < self.config.occlusion_ratio)
            if len(new):
                self.confidence[new] = 1.0
                self._start_group(new, features)
        return self.book.action()
