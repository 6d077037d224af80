"""Object features and Kalman boxes of mask and pose observations (UniTrack appendix C).

Association compares *sets* of location features: a box gives a fixed RoIAlign grid, a mask
the feature-map cells it covers, a pose is first drawn as a mask. The conversions, free of
any environment: :class:`LocalMask` (a mask as its tight crop plus offset, not a full-frame
array per person); :func:`mask_to_box` (appendix C.1: centre = mean in-mask pixel, half
extent = 2 x mean absolute deviation); :func:`pose_to_mask` (appendix C.2: limbs of width
``max(body size / 20, 8)`` plus the filled torso); :func:`mask_grid` /
:func:`mask_location_features` (the in-mask cells of a stride-8 map, capped at ``max_area``
by rescaling: the authors' ``max_mask_area``, 200 MOTS, 1000 VIS). Pixel ``(r, c)`` covers
``[c, c + 1) x [r, r + 1)``, so a tight box is pycocotools' ``toBbox``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from .roi_align import roi_align
from .similarity import ObjectFeatures

MAX_MASK_AREA_MOTS: int = 200
"""Most location features kept per mask on MOTS (authors' ``max_mask_area``)."""

MAX_MASK_AREA_VIS: int = 1000
"""Most location features kept per mask on YouTube-VIS (authors' ``max_mask_area``)."""

MASK_COVERAGE_THRESHOLD: float = 0.5
"""A feature cell belongs to a mask when at least this fraction of its area is in the mask
(the mask "downsampled to the feature grid"). A mask covering no cell that much keeps its
best-covered cell, so that every non-empty mask has at least one location."""

MAD_EXTENT_FACTOR: float = 2.0
"""Half the box extent is this times the mean absolute deviation of the in-mask pixel
coordinates (appendix C.1: for a uniform rectangle of half extent h, the mean |y| is h/2)."""

MIN_BOX_EXTENT: float = 1.0
"""Least width/height (pixels) of a mask's box: a one-pixel-wide mask has zero deviation."""

LIMB_WIDTH_RATIO: float = 0.05
"""Limb width per unit of body size in the pose -> mask conversion (paper: eta_p = 0.05,
i.e. the authors' ``extent / 20``)."""

MIN_LIMB_WIDTH: float = 8.0
"""Least limb width in pixels (authors' code: ``max(extent / 20, 8)``)."""

POSE_LIMBS: tuple[tuple[int, int], ...] = (
    (2, 1),                      # head top - head bottom
    (0, 1),                      # nose - head bottom
    (1, 5), (1, 6),              # head bottom - shoulders (neck)
    (5, 7), (7, 9),              # left arm
    (6, 8), (8, 10),             # right arm
    (5, 6), (5, 11), (6, 12), (11, 12),  # torso outline
    (11, 13), (13, 15),          # left leg
    (12, 14), (14, 16),          # right leg
)
"""Skeleton segments drawn by :func:`pose_to_mask`, as 0-based PoseTrack keypoint indices
(nose, head bottom, head top, left/right ear, shoulders, elbows, wrists, hips, knees, ankles).
The release's own ``skeleton`` field is COCO's (it links the never-annotated ears and leaves
the head bottom unconnected), so the limbs are listed here; ears are not drawn."""

POSE_POLYGONS: tuple[tuple[int, ...], ...] = ((5, 6, 12, 11),)
"""Closed skeleton polygons filled by :func:`pose_to_mask`: the torso (left shoulder, right
shoulder, right hip, left hip). Drawn when at least three of its corners are visible."""

CROP_MARGIN: int = 2
"""Feature cells kept around a mask's box when cropping the map before RoIAlign (bilinear
sampling reads the cell after a sample point; RoIAlign's aligned shift moves points by half
a cell), so that pooling from the crop equals pooling from the whole map."""

SUBPIXEL_BITS: int = 4
"""Fixed-point fraction bits of cv2's drawing calls (1/16-pixel precision)."""


@dataclass(frozen=True)
class LocalMask:
    """A binary mask stored as its bool crop and the crop's top-left pixel ``(x0, y0)``."""

    mask: np.ndarray
    x0: int = 0
    y0: int = 0

    @classmethod
    def from_full(cls, mask: np.ndarray) -> LocalMask:
        """Crop a full-frame ``(H, W)`` mask to its tight box (an empty mask stays 0 x 0)."""
        full = np.asarray(mask, dtype=bool)
        if full.ndim != 2:
            raise ValueError(f"a mask must be 2-d (H, W), got shape {full.shape}")
        rows = np.flatnonzero(full.any(axis=1))
        if not rows.size:
            return cls(np.zeros((0, 0), dtype=bool), 0, 0)
        cols = np.flatnonzero(full.any(axis=0))
        crop = full[rows[0]: rows[-1] + 1, cols[0]: cols[-1] + 1]
        return cls(np.ascontiguousarray(crop), int(cols[0]), int(rows[0]))

    @property
    def area(self) -> int:
        """Number of pixels in the mask."""
        return int(np.count_nonzero(self.mask))

    def tight_box(self) -> np.ndarray:
        """``(x, y, w, h)`` of the crop (the mask's tight box when cropped by :meth:`from_full`)."""
        h, w = self.mask.shape
        return np.array([self.x0, self.y0, w, h], dtype=np.float64)

    def to_full(self, height: int, width: int) -> np.ndarray:
        """Paste the mask into an all-False ``(height, width)`` frame (clipped at its edges)."""
        out = np.zeros((height, width), dtype=bool)
        h, w = self.mask.shape
        x1, y1 = max(self.x0, 0), max(self.y0, 0)
        x2, y2 = min(self.x0 + w, width), min(self.y0 + h, height)
        if x2 > x1 and y2 > y1:
            out[y1:y2, x1:x2] = self.mask[y1 - self.y0: y2 - self.y0, x1 - self.x0: x2 - self.x0]
        return out


def mask_to_box(mask: LocalMask) -> np.ndarray:
    """The paper's box of a mask for the Kalman filter (appendix C.1), ``(x, y, w, h)``.

    Centre: the mean in-mask pixel; half extents: twice the mean absolute deviation (exact for
    a filled rectangle, robust to thin protrusions), floored at :data:`MIN_BOX_EXTENT`.

    >>> m = np.zeros((6, 8), bool); m[1:5, 2:8] = True   # a 6 x 4 rectangle at (2, 1)
    >>> mask_to_box(LocalMask.from_full(m)).tolist()
    [2.0, 1.0, 6.0, 4.0]
    """
    ys, xs = np.nonzero(mask.mask)
    if not len(xs):
        raise ValueError("an empty mask has no box; drop empty masks before association")
    px = xs.astype(np.float64) + (mask.x0 + 0.5)
    py = ys.astype(np.float64) + (mask.y0 + 0.5)
    u, v = px.mean(), py.mean()
    half_w = max(MAD_EXTENT_FACTOR * np.abs(px - u).mean(), MIN_BOX_EXTENT / 2)
    half_h = max(MAD_EXTENT_FACTOR * np.abs(py - v).mean(), MIN_BOX_EXTENT / 2)
    return np.array([u - half_w, v - half_h, 2 * half_w, 2 * half_h])


def body_size(keypoints: np.ndarray, min_score: float = 0.0) -> float:
    """Body size of a pose: ``max(x range, y range)`` of keypoints scored above ``min_score``."""
    kp = np.asarray(keypoints, dtype=np.float64)
    visible = kp[kp[:, 2] > min_score, :2]
    if not len(visible):
        return 0.0
    extent = visible.max(axis=0) - visible.min(axis=0)
    return float(extent.max())


def pose_to_mask(
    keypoints: np.ndarray,
    *,
    min_score: float = 0.0,
    limbs: Sequence[tuple[int, int]] = POSE_LIMBS,
    polygons: Sequence[Sequence[int]] = POSE_POLYGONS,
    width_ratio: float = LIMB_WIDTH_RATIO,
    min_width: float = MIN_LIMB_WIDTH,
) -> LocalMask | None:
    """Draw a pose as a binary mask (the paper's pose -> mask conversion, appendix C.2).

    Limbs with both keypoints visible (score above ``min_score``) become round-capped segments
    of width ``max(width_ratio * body_size, min_width)`` (paper 0.05, code 8 px), polygons with
    three visible corners are filled, visible keypoints get discs. None when none is visible.

    >>> kp = np.zeros((17, 3)); kp[5] = (50, 40, 1); kp[11] = (50, 90, 1)
    >>> m = pose_to_mask(kp)
    >>> (m.x0, m.y0, m.mask.shape)   # a ~8-pixel-wide vertical stroke with round caps
    (46, 36, (59, 9))
    """
    kp = np.asarray(keypoints, dtype=np.float64)
    if kp.ndim != 2 or kp.shape[1] != 3:
        raise ValueError(f"keypoints must be (K, 3) as (x, y, score), got shape {kp.shape}")
    if not np.all(np.isfinite(kp)):
        raise ValueError("keypoints contain NaN or infinite values")
    visible = kp[:, 2] > min_score
    if not visible.any():
        return None
    width = max(width_ratio * body_size(kp, min_score), min_width)
    return _draw_pose(kp, visible, width, limbs, polygons)


def _draw_pose(
    kp: np.ndarray, visible: np.ndarray, width: float, limbs: Sequence[tuple[int, int]],
    polygons: Sequence[Sequence[int]],
) -> LocalMask:
    """Draw the visible limbs, polygons and joint discs of a pose; crop to the drawn pixels."""
    radius = width / 2.0
    pts = kp[visible, :2]
    x0 = int(math.floor(pts[:, 0].min() - radius)) - 1
    y0 = int(math.floor(pts[:, 1].min() - radius)) - 1
    x1 = int(math.ceil(pts[:, 0].max() + radius)) + 1
    y1 = int(math.ceil(pts[:, 1].max() + radius)) + 1
    canvas = np.zeros((y1 - y0, x1 - x0), dtype=np.uint8)
    scale = 1 << SUBPIXEL_BITS
    # cv2 puts integer coordinates at pixel centres; continuous x maps to x - 0.5.
    fixed = np.round((kp[:, :2] - (x0 + 0.5, y0 + 0.5)) * scale).astype(np.int64)
    thickness = max(1, int(round(width)))
    for a, b in limbs:
        if visible[a] and visible[b]:
            cv2.line(canvas, tuple(int(v) for v in fixed[a]), tuple(int(v) for v in fixed[b]),
                     1, thickness=thickness, lineType=cv2.LINE_8, shift=SUBPIXEL_BITS)
    for polygon in polygons:
        corners = [i for i in polygon if visible[i]]
        if len(corners) >= 3:
            cv2.fillPoly(canvas, [fixed[corners].astype(np.int32)], 1, lineType=cv2.LINE_8,
                         shift=SUBPIXEL_BITS)
    radius_fixed = int(round(radius * scale))
    for i in np.flatnonzero(visible):
        cv2.circle(canvas, tuple(int(v) for v in fixed[i]), radius_fixed, 1, thickness=-1,
                   lineType=cv2.LINE_8, shift=SUBPIXEL_BITS)
    local = LocalMask(canvas.astype(bool), x0, y0)
    # Crop to the drawn pixels so that tight_box() is the mask's tight box.
    cropped = LocalMask.from_full(local.mask)
    return LocalMask(cropped.mask, cropped.x0 + x0, cropped.y0 + y0)


def mask_grid(
    mask: LocalMask,
    box_features: np.ndarray,
    max_area: int | None,
    coverage_threshold: float = MASK_COVERAGE_THRESHOLD,
) -> np.ndarray:
    """The mask's cells on a grid over its box in feature-map units, capped at ``max_area``.

    About one grid cell per feature cell; a cell is in when its covered fraction reaches
    ``coverage_threshold``. Over ``max_area`` cells, the grid shrinks by
    ``sqrt(max_area / count)`` per axis (the authors' "rescaling" cap). At least one cell is in.
    """
    if max_area is not None and max_area < 1:
        raise ValueError(f"max_area must be >= 1 or None, got {max_area}")
    x1, y1, x2, y2 = (float(v) for v in box_features)
    rows = max(1, int(round(y2 - y1)))
    cols = max(1, int(round(x2 - x1)))
    source = mask.mask.astype(np.float32)
    while True:
        coverage = cv2.resize(source, (cols, rows), interpolation=cv2.INTER_AREA)
        coverage = coverage.reshape(rows, cols)
        inside = coverage >= coverage_threshold
        if not inside.any():
            inside = coverage >= coverage.max()
        count = int(inside.sum())
        if max_area is None or count <= max_area:
            return inside
        shrink = math.sqrt(max_area / count)
        rows, cols = max(1, int(rows * shrink)), max(1, int(cols * shrink))


def mask_location_features(
    feature_map: torch.Tensor,
    masks: Sequence[LocalMask],
    to_features: Callable[[np.ndarray], np.ndarray],
    *,
    max_area: int | None = MAX_MASK_AREA_MOTS,
    sampling_ratio: int = 2,
    coverage_threshold: float = MASK_COVERAGE_THRESHOLD,
    normalize: bool = True,
) -> list[ObjectFeatures]:
    """In-mask location features of each mask: a variable-size set per object.

    RoIAlign pools ``feature_map`` on each mask's :func:`mask_grid`; the cells inside the mask
    are kept, L2-normalised, with their grid positions (for CF). ``to_features`` maps frame
    x1y1x2y2 boxes to feature coordinates.
    """
    fmap = feature_map.unsqueeze(0) if feature_map.ndim == 3 else feature_map
    if not masks:
        return []
    boxes = np.stack([
        np.array([m.x0, m.y0, m.x0 + m.mask.shape[1], m.y0 + m.mask.shape[0]], np.float64)
        for m in masks
    ])
    feat_boxes = np.asarray(to_features(boxes), dtype=np.float64).reshape(-1, 4)
    return [
        _mask_features(fmap, mask, fbox, max_area, sampling_ratio, coverage_threshold, normalize)
        for mask, fbox in zip(masks, feat_boxes, strict=True)
    ]


def _mask_features(
    fmap: torch.Tensor, mask: LocalMask, fbox: np.ndarray, max_area: int | None,
    sampling_ratio: int, coverage_threshold: float, normalize: bool,
) -> ObjectFeatures:
    """One mask's in-mask location features (see :func:`mask_location_features`)."""
    if mask.area == 0:
        raise ValueError("empty mask: drop empty masks before computing features")
    inside = mask_grid(mask, fbox, max_area, coverage_threshold)
    rows, cols = inside.shape
    # Pool from a crop of the map around the box (margin: the bilinear neighbours), so
    # that RoIAlign does not touch (or pad) the whole map once per mask; same values.
    height, width = fmap.shape[-2:]
    cx1 = min(max(int(math.floor(fbox[0])) - CROP_MARGIN, 0), width - 1)
    cy1 = min(max(int(math.floor(fbox[1])) - CROP_MARGIN, 0), height - 1)
    cx2 = max(min(int(math.ceil(fbox[2])) + CROP_MARGIN, width), cx1 + 1)
    cy2 = max(min(int(math.ceil(fbox[3])) + CROP_MARGIN, height), cy1 + 1)
    crop = fmap[:, :, cy1:cy2, cx1:cx2]
    roi = torch.as_tensor((fbox - (cx1, cy1, cx1, cy1))[None], dtype=fmap.dtype)
    pooled = roi_align(crop, roi, (rows, cols), spatial_scale=1.0,
                       sampling_ratio=sampling_ratio)[0]  # (C, rows, cols)
    flat = pooled.flatten(1).T  # (rows * cols, C), row-major
    index = torch.as_tensor(np.flatnonzero(inside.reshape(-1)))
    features = flat[index]
    if normalize:
        features = F.normalize(features, dim=1)
    r, c = np.divmod(index.numpy(), cols)
    bin_h = (fbox[3] - fbox[1]) / rows
    bin_w = (fbox[2] - fbox[0]) / cols
    positions = np.stack([fbox[1] + (r + 0.5) * bin_h, fbox[0] + (c + 0.5) * bin_w], axis=1)
    return ObjectFeatures(features, torch.as_tensor(positions, dtype=torch.float64))
