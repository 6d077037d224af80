import math

import pytest
import torch

from unitrack_env.agents.primitives.roi_align import roi_align


def _ramp(channels: int = 3, height: int = 20, width: int = 30) -> tuple[torch.Tensor, list]:
    """f_c(y, x) = a_c * x + b_c * y + c_c on the pixel grid (index coordinates)."""
    coeffs = [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.5, -2.0, 3.0)][:channels]
    y, x = torch.meshgrid(
        torch.arange(height, dtype=torch.float64), torch.arange(width, dtype=torch.float64),
        indexing="ij",
    )
    fmap = torch.stack([a * x + b * y + c for a, b, c in coeffs])
    return fmap, coeffs


@pytest.mark.parametrize("aligned", [True, False])
def test_linear_ramp_gives_the_analytic_bin_centres(aligned: bool) -> None:
    # Bilinear interpolation of a linear function is exact inside the map, and the mean of
    # the symmetric samples of a bin is the value at the bin centre.
    fmap, coeffs = _ramp()
    box = (3.0, 2.0, 11.0, 17.0)  # x1, y1, x2, y2: well inside the 30 x 20 map
    out = roi_align(fmap, torch.tensor([box], dtype=torch.float64), (10, 4), aligned=aligned)
    assert out.shape == (1, 3, 10, 4)
    shift = 0.5 if aligned else 0.0
    x1, y1, x2, y2 = box
    bin_w, bin_h = (x2 - x1) / 4, (y2 - y1) / 10
    for ph in range(10):
        for pw in range(4):
            cx = x1 - shift + (pw + 0.5) * bin_w
            cy = y1 - shift + (ph + 0.5) * bin_h
            for ch, (a, b, c) in enumerate(coeffs):
                assert out[0, ch, ph, pw].item() == pytest.approx(a * cx + b * cy + c, abs=1e-9)


def test_spatial_scale_maps_image_boxes_to_feature_coordinates() -> None:
    fmap, _ = _ramp()
    image_boxes = torch.tensor(
        [[24.0, 16.0, 88.0, 136.0], [0.0, 0.0, 40.0, 8.0]], dtype=torch.float64
    )
    a = roi_align(fmap, image_boxes, (10, 4), spatial_scale=1 / 8)
    b = roi_align(fmap, image_boxes / 8, (10, 4))
    torch.testing.assert_close(a, b)


def test_empty_boxes() -> None:
    fmap = torch.randn(5, 7, 9)
    out = roi_align(fmap, torch.zeros((0, 4)))
    assert out.shape == (0, 5, 10, 4)
    assert roi_align(fmap, []).shape == (0, 5, 10, 4)


def test_batches_and_torchvision_style_rows() -> None:
    fmaps = torch.stack([torch.zeros(2, 6, 6), torch.ones(2, 6, 6)])
    boxes = torch.tensor([[1.0, 1.0, 4.0, 4.0], [1.0, 1.0, 4.0, 4.0]])
    out = roi_align(fmaps, boxes, (2, 2), batch_index=[1, 0])
    assert torch.all(out[0] == 1) and torch.all(out[1] == 0)
    rows = torch.cat([torch.tensor([[1.0], [0.0]]), boxes], dim=1)
    torch.testing.assert_close(roi_align(fmaps, rows, (2, 2)), out)
    with pytest.raises(ValueError, match="batch_index"):
        roi_align(fmaps, boxes, (2, 2))
    with pytest.raises(ValueError, match="batch indices"):
        roi_align(fmaps, boxes, (2, 2), batch_index=[0, 2])
    with pytest.raises(ValueError, match="boxes"):
        roi_align(fmaps[0], torch.zeros(3, 3), (2, 2))


def _reference(fmap: torch.Tensor, boxes: list, out: tuple[int, int], scale: float,
               ratio: int, aligned: bool) -> torch.Tensor:
    """Scalar loops over torchvision's documented RoIAlign rules (the slow, obvious way)."""
    channels, height, width = fmap.shape
    result = torch.zeros(len(boxes), channels, *out, dtype=torch.float64)

    def bilinear(y: float, x: float) -> torch.Tensor:
        if y < -1 or y > height or x < -1 or x > width:
            return torch.zeros(channels, dtype=torch.float64)
        y, x = max(y, 0.0), max(x, 0.0)
        yl, xl = int(y), int(x)
        if yl >= height - 1:
            yh = yl = height - 1
            y = float(yl)
        else:
            yh = yl + 1
        if xl >= width - 1:
            xh = xl = width - 1
            x = float(xl)
        else:
            xh = xl + 1
        ly, lx = y - yl, x - xl
        return ((1 - ly) * (1 - lx) * fmap[:, yl, xl] + (1 - ly) * lx * fmap[:, yl, xh]
                + ly * (1 - lx) * fmap[:, yh, xl] + ly * lx * fmap[:, yh, xh])

    off = 0.5 if aligned else 0.0
    for n, (x1, y1, x2, y2) in enumerate(boxes):
        sw, sh = x1 * scale - off, y1 * scale - off
        rw, rh = x2 * scale - off - sw, y2 * scale - off - sh
        if not aligned:
            rw, rh = max(rw, 1.0), max(rh, 1.0)
        bh, bw = rh / out[0], rw / out[1]
        gh = ratio if ratio > 0 else math.ceil(rh / out[0])
        gw = ratio if ratio > 0 else math.ceil(rw / out[1])
        for ph in range(out[0]):
            for pw in range(out[1]):
                acc = torch.zeros(channels, dtype=torch.float64)
                for iy in range(gh):
                    for ix in range(gw):
                        acc += bilinear(sh + ph * bh + (iy + 0.5) * bh / gh,
                                        sw + pw * bw + (ix + 0.5) * bw / gw)
                result[n, :, ph, pw] = acc / max(gh * gw, 1)
    return result


@pytest.mark.parametrize("ratio", [2, 0, 3])
@pytest.mark.parametrize("aligned", [True, False])
def test_matches_scalar_reference_including_borders(ratio: int, aligned: bool) -> None:
    g = torch.Generator().manual_seed(ratio + 10 * aligned)
    fmap = torch.randn(3, 9, 13, generator=g, dtype=torch.float64)
    corners = torch.rand(15, 4, generator=g, dtype=torch.float64) * torch.tensor(
        [18.0, 14.0, 18.0, 14.0]
    ) - 2.0  # many boxes cross or leave the map
    boxes = torch.stack([
        corners[:, 0].minimum(corners[:, 2]), corners[:, 1].minimum(corners[:, 3]),
        corners[:, 0].maximum(corners[:, 2]), corners[:, 1].maximum(corners[:, 3]),
    ], dim=1)
    boxes[0] = torch.tensor([4.0, 4.0, 4.0, 4.0])  # degenerate box
    for scale in (1.0, 0.5):
        got = roi_align(fmap, boxes, (5, 3), spatial_scale=scale, sampling_ratio=ratio,
                        aligned=aligned)
        want = _reference(fmap, boxes.tolist(), (5, 3), scale, ratio, aligned)
        torch.testing.assert_close(got, want, atol=1e-12, rtol=0)


def test_dtype_is_kept_and_a_constant_map_pools_to_the_constant() -> None:
    fmap = torch.randn(4, 8, 8)
    out = roi_align(fmap, torch.tensor([[0.0, 0.0, 8.0, 8.0]]))
    assert out.dtype == torch.float32 and out.shape == (1, 4, 10, 4)
    # A box covering the whole constant map pools to the constant everywhere.
    const = torch.full((2, 8, 8), 3.0)
    torch.testing.assert_close(
        roi_align(const, torch.tensor([[0.0, 0.0, 8.0, 8.0]])), torch.full((1, 2, 10, 4), 3.0)
    )
