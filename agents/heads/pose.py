"""The UniTrack pose-propagation head (``unitrack-pose``): belief maps propagated like masks.

UniTrack paper, section 2.3 and appendix B.2; JHMDB table of appendix E. Per video:

1. Each frame is resized to ``input_size`` (the paper's 320 x 320; None: native) and goes
   once through the backbone.
2. At reset each of the ``J`` joints becomes a Gaussian belief map on the feature grid with
   ``sigma = max(eta * s_body, 0.5)`` feature pixels (``eta = 0.01``, ``s_body`` the larger
   side of the joints' box; the floor is half a cell, as sharp as the grid allows).
3. Later frames: the ``J`` maps are propagated together by
   :class:`~unitrack_env.agents.primitives.label_propagation.LabelPropagator`.
4. Decoding: the argmax of each map refined by a soft-argmax over its
   ``(2 refine_radius + 1)^2`` neighbourhood (sub-cell positions, not pulled by far-away
   secondary modes as a global soft-argmax would); a map whose peak is below ``min_peak``
   keeps the joint's previous position.

Keypoints are ``(x, y)`` 0-based pixels with integer centres; feature cell ``j`` of ``n``
cells over ``N`` pixels is centred at ``(j + 0.5) * N / n - 0.5`` (``align_corners=False``).
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
from .vos import PropagationHeadConfig

POSE_INPUT_SIZE: tuple[int, int] = (320, 320)
"""(width, height) frames are resized to (appendix B.2 table, "Pose: 320 x 320")."""

SIGMA_ETA: float = 0.01
"""``eta``: Gaussian sigma per unit of body size (appendix B.2 table)."""

MIN_SIGMA: float = 0.5
"""Least Gaussian sigma, in feature pixels (appendix B.2: ``sigma = max(eta s_body, 0.5)``)."""

REFINE_RADIUS: int = 1
"""Half-side (feature cells) of the soft-argmax neighbourhood around each map's argmax."""

MIN_PEAK: float = 1e-3
"""A propagated map whose maximum is below this has lost its joint: keep the last position."""


@dataclass(frozen=True)
class UniTrackPoseConfig(PropagationHeadConfig):
    """Options of ``unitrack-pose``: :class:`PropagationHeadConfig`'s and the belief maps'.

    ``input_size = (320, 320)`` [appendix B.2] frames resized to (width, height), None: native;
    ``sigma_eta = 0.01`` [0.01] and ``min_sigma = 0.5`` [0.5] in
    ``sigma = max(eta * s_body, min_sigma)`` (feature pixels); ``refine_radius = 1``
    soft-argmax half-side (0: plain argmax); ``min_peak = 1e-3``: a joint whose map peaks
    below keeps its previous position.
    """

    input_size: tuple[int, int] | None = POSE_INPUT_SIZE
    sigma_eta: float = SIGMA_ETA
    min_sigma: float = MIN_SIGMA
    refine_radius: int = REFINE_RADIUS
    min_peak: float = MIN_PEAK


def belief_maps(points: np.ndarray, shape: tuple[int, int], sigma: float) -> torch.Tensor:
    """``(J, h, w)`` Gaussian maps centred on ``points`` ``(J, 2)`` (x, y in grid cells)."""
    h, w = shape
    ys = torch.arange(h, dtype=torch.float64).view(1, h, 1)
    xs = torch.arange(w, dtype=torch.float64).view(1, 1, w)
    pts = torch.as_tensor(np.asarray(points, np.float64))
    d2 = (xs - pts[:, 0].view(-1, 1, 1)) ** 2 + (ys - pts[:, 1].view(-1, 1, 1)) ** 2
    return torch.exp(-d2 / (2.0 * sigma * sigma)).float()


def body_size(points: np.ndarray) -> float:
    """``s_body``: the larger side of the joints' bounding box (paper eq. sbody)."""
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    return float(max(np.ptp(pts[:, 0]), np.ptp(pts[:, 1]))) if len(pts) else 0.0


def decode_maps(maps: torch.Tensor, refine_radius: int = REFINE_RADIUS) -> tuple[np.ndarray,
                                                                                 np.ndarray]:
    """Peak ``(J, 2)`` (x, y) in grid cells and ``(J,)`` values of ``(J, h, w)`` maps."""
    maps = maps.double()
    j, h, w = maps.shape
    flat = maps.reshape(j, -1)
    peak, index = flat.max(dim=1)
    rows, cols = (index // w).numpy(), (index % w).numpy()
    out = np.zeros((j, 2))
    for k in range(j):
        r0, r1 = max(0, rows[k] - refine_radius), min(h, rows[k] + refine_radius + 1)
        c0, c1 = max(0, cols[k] - refine_radius), min(w, cols[k] + refine_radius + 1)
        patch = maps[k, r0:r1, c0:c1].clamp(min=0)
        total = float(patch.sum())
        if total <= 0:
            out[k] = (cols[k], rows[k])
            continue
        yy, xx = torch.meshgrid(torch.arange(r0, r1, dtype=torch.float64),
                                torch.arange(c0, c1, dtype=torch.float64), indexing="ij")
        out[k] = (float((patch * xx).sum()) / total, float((patch * yy).sum()) / total)
    return out, peak.numpy()


class UniTrackPoseAgent(Agent, name="unitrack-pose", tasks=("pose-prop",)):
    """UniTrack's pose-propagation head (JHMDB): joints as Gaussian belief maps, propagated.

    ``appearance_model``: a model shared with other heads; ``**options``:
    :class:`UniTrackPoseConfig` fields.
    """

    config_class = UniTrackPoseConfig

    def __init__(self, *, appearance_model: AppearanceModel | None = None,
                 **options: Any) -> None:
        self.config, self.model = UniTrackPoseConfig.configure(self.name, options, appearance_model)
        self.propagator = LabelPropagator(self.config.propagation_config(self.model.stride))
        self.sigma = self.config.min_sigma
        self._pose: np.ndarray | None = None
        self._first_answer: np.ndarray | None = None
        self._frame_size = (1.0, 1.0)  # (width, height) of frame pixels the grid covers
        self._grid = (1, 1)  # (w, h) of the feature map
        self.cached = with_cache(self.model, self.config.feature_cache)  # float32: exact

    # ------------------------------------------------------------------ coordinates
    def _to_grid(self, points: np.ndarray) -> np.ndarray:
        (fw, fh), (gw, gh) = self._frame_size, self._grid
        return (np.asarray(points, np.float64) + 0.5) * np.array([gw / fw, gh / fh]) - 0.5

    def _to_frame(self, points: np.ndarray) -> np.ndarray:
        (fw, fh), (gw, gh) = self._frame_size, self._grid
        return (np.asarray(points, np.float64) + 0.5) * np.array([fw / gw, fh / gh]) - 0.5

    def _features(self, frame: np.ndarray) -> torch.Tensor:
        size = self.config.input_size
        if size is not None and (frame.shape[1], frame.shape[0]) != tuple(size):
            frame = cv2.resize(np.ascontiguousarray(frame), tuple(size),
                               interpolation=cv2.INTER_LINEAR)
        return self.cached.features(frame)[0]

    # ------------------------------------------------------------------ episode
    def reset(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        """Build the first frame's belief maps and start the memory bank."""
        pose = np.array(observation["init_keypoints"], dtype=np.float64)
        frame = observation["frame"]
        with torch_threads(self.config.num_threads), torch.inference_mode():
            features = self._features(frame)
            self._grid = (features.shape[2], features.shape[1])
            # the input pixels the map spans (a ViT's whole patches: more than the input
            # when the patch does not divide it), in frame pixels
            width, height = self.config.input_size or (frame.shape[1], frame.shape[0])
            rows, cols = self.model.map_extent(height, width)
            self._frame_size = (cols * frame.shape[1] / width, rows * frame.shape[0] / height)
            grid_points = self._to_grid(pose)
            self.sigma = max(self.config.sigma_eta * body_size(grid_points),
                             self.config.min_sigma)
            maps = belief_maps(grid_points, (features.shape[1], features.shape[2]), self.sigma)
            self.propagator.reset(features, maps.to(features.device))
        self._pose = pose
        self._first_answer = pose.astype(np.float32)

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        """The ``(J, 2)`` float32 joints ``(x, y)`` of the current frame."""
        if self._first_answer is not None:  # the first step answers the reset frame
            answer, self._first_answer = self._first_answer, None
            return answer
        if self._pose is None:
            raise RuntimeError("call reset() with the first observation before act()")
        with torch_threads(self.config.num_threads), torch.inference_mode():
            maps = self.propagator.step(self._features(observation["frame"]))
        cells, peaks = decode_maps(maps.cpu(), self.config.refine_radius)
        pose = self._to_frame(cells)
        lost = peaks < self.config.min_peak
        pose[lost] = self._pose[lost]
        self._pose = pose
        return pose.astype(np.float32)
