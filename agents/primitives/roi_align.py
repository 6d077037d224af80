"""RoIAlign in pure, vectorised torch (no torchvision).

RoIAlign (He et al., Mask R-CNN, ICCV 2017) pools a fixed grid of features from any box by
averaging bilinear samples in each bin, with torchvision's semantics exactly: ``aligned=True``
shifts box coordinates by -0.5 (pixel centres on integers; ``False``: no shift, boxes at
least 1 x 1); each bin averages ``sampling_ratio`` squared samples (adaptive
``ceil(box / output)`` when not positive); a sample more than one pixel outside the map
contributes 0 but counts, samples in ``[-1, 0)`` are clamped. UniTrack pools each detection
box from the stride-8 map into a tall 10 x 4 grid: 40 location features per box.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

DEFAULT_OUTPUT_SIZE: tuple[int, int] = (10, 4)
"""(height, width) of pooled box features: a tall grid for pedestrians (40 locations)."""

DEFAULT_SAMPLING_RATIO: int = 2
"""Bilinear samples per bin along each axis."""


def _axis_samples(
    start: torch.Tensor, size: torch.Tensor, bins: int, grid: torch.Tensor, max_grid: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Sample coordinates ``(n, bins, max_grid)`` along one axis and their validity mask."""
    bin_size = size / bins
    ph = torch.arange(bins, dtype=start.dtype, device=start.device).view(1, bins, 1)
    it = torch.arange(max_grid, dtype=start.dtype, device=start.device).view(1, 1, max_grid)
    g = grid.to(start.dtype).clamp(min=1).view(-1, 1, 1)
    coords = start.view(-1, 1, 1) + ph * bin_size.view(-1, 1, 1) + (it + 0.5) * (
        bin_size.view(-1, 1, 1) / g
    )
    used = it < grid.view(-1, 1, 1)
    return coords, used.expand(-1, bins, -1)


def _interp_axis(
    coords: torch.Tensor, length: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """One axis of torchvision's bilinear rule: (low, high, w_low, w_high, inside)."""
    inside = (coords >= -1.0) & (coords <= length)
    c = coords.clamp(min=0.0)
    low = c.floor().to(torch.long)
    at_end = low >= length - 1
    low = torch.where(at_end, torch.full_like(low, length - 1), low)
    high = torch.where(at_end, low, low + 1)
    c = torch.where(at_end, low.to(c.dtype), c)
    w_high = c - low.to(c.dtype)
    w_low = 1.0 - w_high
    return low, high, w_low, w_high, inside


def roi_align(
    feature_map: torch.Tensor,
    boxes: torch.Tensor | Sequence[Sequence[float]],
    output_size: tuple[int, int] = DEFAULT_OUTPUT_SIZE,
    *,
    spatial_scale: float = 1.0,
    sampling_ratio: int = DEFAULT_SAMPLING_RATIO,
    aligned: bool = True,
    batch_index: torch.Tensor | Sequence[int] | None = None,
) -> torch.Tensor:
    """Pool a fixed ``output_size`` feature grid from each box: ``(n, C, oh, ow)``.

    ``boxes`` are ``(n, 4)`` x1y1x2y2 (or torchvision's ``(n, 5)`` with a batch index) that
    ``spatial_scale`` maps to feature pixels. ``sampling_ratio <= 0`` picks
    ``ceil(box_size / output_size)`` per box; ``aligned`` shifts boxes by -0.5 pixel. A batched
    map with ``B > 1`` needs ``batch_index``; bad shapes raise ValueError.
    """
    fmap = feature_map.unsqueeze(0) if feature_map.ndim == 3 else feature_map
    if fmap.ndim != 4:
        raise ValueError(
            f"feature_map must be (C, H, W) or (B, C, H, W); got {tuple(feature_map.shape)}"
        )
    num_images, channels = fmap.shape[:2]
    pooled_h, pooled_w = (int(v) for v in output_size)
    if pooled_h < 1 or pooled_w < 1:
        raise ValueError(f"output_size must be positive, got {output_size}")
    dtype = fmap.dtype if fmap.is_floating_point() else torch.float32
    rois = torch.as_tensor(boxes, dtype=dtype, device=fmap.device)
    if rois.numel() == 0:
        return fmap.new_zeros((0, channels, pooled_h, pooled_w), dtype=dtype)
    if rois.ndim != 2 or rois.shape[1] not in (4, 5):
        raise ValueError(f"boxes must be (n, 4) x1y1x2y2 or (n, 5); got {tuple(rois.shape)}")
    rois, index = _split_batch_index(rois, batch_index, num_images)
    return _pool(fmap.to(dtype), rois, index, (pooled_h, pooled_w), spatial_scale,
                 sampling_ratio, aligned)


def _split_batch_index(
    rois: torch.Tensor, batch_index: torch.Tensor | Sequence[int] | None, num_images: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(n, 4)`` boxes and the image of each, from ``(n, 5)`` rows or ``batch_index``."""
    if rois.shape[1] == 5:
        if batch_index is not None:
            raise ValueError("give the batch index either as boxes[:, 0] or batch_index, not both")
        index = rois[:, 0].round().to(torch.long)
        rois = rois[:, 1:]
    elif batch_index is not None:
        index = torch.as_tensor(batch_index, dtype=torch.long, device=rois.device).view(-1)
        if index.numel() != rois.shape[0]:
            raise ValueError(f"batch_index has {index.numel()} entries for {rois.shape[0]} boxes")
    elif num_images == 1:
        index = torch.zeros(rois.shape[0], dtype=torch.long, device=rois.device)
    else:
        raise ValueError(f"feature_map holds {num_images} images: pass batch_index for the boxes")
    if index.numel() and (index.min() < 0 or index.max() >= num_images):
        raise ValueError(f"batch indices must be in [0, {num_images}); got {index.tolist()}")
    return rois, index


def _sampling_grid(
    rois: torch.Tensor, pooled: tuple[int, int], spatial_scale: float, sampling_ratio: int,
    aligned: bool,
) -> tuple[torch.Tensor, ...]:
    """``(x1, y1, roi_w, roi_h, grid_h, grid_w)`` per box: origins, sizes, samples per bin."""
    offset = 0.5 if aligned else 0.0
    x1 = rois[:, 0] * spatial_scale - offset
    y1 = rois[:, 1] * spatial_scale - offset
    roi_w = rois[:, 2] * spatial_scale - offset - x1
    roi_h = rois[:, 3] * spatial_scale - offset - y1
    if not aligned:
        roi_w = roi_w.clamp(min=1.0)
        roi_h = roi_h.clamp(min=1.0)
    if sampling_ratio > 0:
        grid_h = torch.full_like(roi_h, sampling_ratio, dtype=torch.long)
        grid_w = torch.full_like(roi_w, sampling_ratio, dtype=torch.long)
    else:
        grid_h = torch.ceil(roi_h / pooled[0]).to(torch.long).clamp(min=0)
        grid_w = torch.ceil(roi_w / pooled[1]).to(torch.long).clamp(min=0)
    return x1, y1, roi_w, roi_h, grid_h, grid_w


def _pool(
    fmap: torch.Tensor, rois: torch.Tensor, index: torch.Tensor, pooled: tuple[int, int],
    spatial_scale: float, sampling_ratio: int, aligned: bool,
) -> torch.Tensor:
    """Average the bilinear samples of every bin: ``(n, C, pooled_h, pooled_w)``."""
    _, channels, height, width = fmap.shape
    dtype = fmap.dtype
    pooled_h, pooled_w = pooled
    x1, y1, roi_w, roi_h, grid_h, grid_w = _sampling_grid(
        rois, pooled, spatial_scale, sampling_ratio, aligned)
    max_gh = max(int(grid_h.max()), 1)
    max_gw = max(int(grid_w.max()), 1)

    ys, used_y = _axis_samples(y1, roi_h, pooled_h, grid_h, max_gh)  # (n, PH, GH)
    xs, used_x = _axis_samples(x1, roi_w, pooled_w, grid_w, max_gw)  # (n, PW, GW)
    n = rois.shape[0]
    y_low, y_high, wy_low, wy_high, in_y = _interp_axis(ys.reshape(n, -1), height)
    x_low, x_high, wx_low, wx_high, in_x = _interp_axis(xs.reshape(n, -1), width)
    keep_y = (in_y & used_y.reshape(n, -1)).to(dtype)
    keep_x = (in_x & used_x.reshape(n, -1)).to(dtype)

    values = fmap.permute(0, 2, 3, 1)  # (B, H, W, C)
    b = index.view(n, 1, 1)

    def corner(yi: torch.Tensor, xi: torch.Tensor) -> torch.Tensor:
        return values[b, yi.unsqueeze(2), xi.unsqueeze(1)]  # (n, Sy, Sx, C)

    wy_low, wy_high = (wy_low * keep_y).unsqueeze(2), (wy_high * keep_y).unsqueeze(2)
    wx_low, wx_high = (wx_low * keep_x).unsqueeze(1), (wx_high * keep_x).unsqueeze(1)
    sampled = (
        corner(y_low, x_low) * (wy_low * wx_low).unsqueeze(-1)
        + corner(y_low, x_high) * (wy_low * wx_high).unsqueeze(-1)
        + corner(y_high, x_low) * (wy_high * wx_low).unsqueeze(-1)
        + corner(y_high, x_high) * (wy_high * wx_high).unsqueeze(-1)
    )  # (n, PH*GH, PW*GW, C)
    pooled_sum = sampled.view(n, pooled_h, max_gh, pooled_w, max_gw, channels).sum(dim=(2, 4))
    count = (grid_h * grid_w).clamp(min=1).to(dtype).view(n, 1, 1, 1)
    return (pooled_sum / count).permute(0, 3, 1, 2).contiguous()
