"""Box propagation (level 2): crops, windows, DCF and XCorr responses, and a tracker that
follows a known motion with the exact displacement scale (window / 65 per feature pixel)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from unitrack_env.agents.primitives.box_propagation import (
    BoxPropagationConfig,
    BoxPropagator,
    BoxState,
    DCFHead,
    XCorrHead,
    crop_windows,
    gaussian_label,
    hann_window,
    response_peak,
)


def test_paper_defaults():
    cfg = BoxPropagationConfig()
    assert (cfg.crop_size, cfg.context, cfg.dcf_lambda, cfg.dcf_interp) == (520, 4.5, 1e-4, 1e-2)
    np.testing.assert_allclose(cfg.scale_factors(), [1 / 1.0275, 1.0, 1.0275])
    np.testing.assert_allclose(cfg.scale_penalties(), [0.985, 1.0, 0.985])
    with pytest.raises(ValueError, match="method"):
        BoxPropagationConfig(method="kcf")
    with pytest.raises(ValueError, match="odd"):
        BoxPropagationConfig(num_scales=2)
    with pytest.raises(ValueError, match="template_window"):
        BoxPropagationConfig(template_window=0.0)


def test_crop_at_unit_scale_is_the_image_block_and_pads_with_the_mean():
    rng = np.random.default_rng(0)
    image = rng.integers(0, 255, (40, 50, 3), dtype=np.uint8)
    crop = crop_windows(image, (25.0, 20.0), np.array([[16.0, 16.0]]), 16)[0]
    np.testing.assert_array_equal(crop, image[12:28, 17:33])
    outside = crop_windows(image, (-100.0, -100.0), np.array([[8.0, 8.0]]), 8,
                           fill=(1.0, 2.0, 3.0))[0]
    assert (outside == [1, 2, 3]).all()


def test_a_crop_is_a_continuous_function_of_the_box():
    """Float noise of a box (1e-6 px) moves the crop by about as much, never a grey level:
    the cause of SOT results that moved by 10 AUC points between runtimes (issue 38)."""
    rng = np.random.default_rng(1)
    image = rng.integers(0, 255, (60, 80, 3), dtype=np.uint8)
    windows = np.array([[37.3, 29.1], [38.2, 29.9]])
    crop = crop_windows(image, (40.123, 30.456), windows, 64)
    moved = crop_windows(image, (40.123 + 1e-6, 30.456 - 1e-6), windows * (1 + 1e-9), 64)
    assert crop.dtype == np.float32
    assert 0 < np.abs(moved - crop).max() < 1e-3
    # x = 10.0 is the edge between columns 9 and 10 (row 5 centred at y = 5.5): their mean
    half = crop_windows(image, (10.0, 5.5), np.array([[1.0, 1.0]]), 1)[0, 0, 0]
    np.testing.assert_allclose(half, image[5, 9:11].astype(np.float64).mean(0), rtol=1e-6)


def test_windows_and_labels():
    win = hann_window(9)
    assert win[4, 4] == pytest.approx(1.0) and win[0, 4] == 0.0
    label = gaussian_label(9, 1.0)
    assert label[0, 0] == 1.0 and label[1, 0] == pytest.approx(np.exp(-0.5))
    assert label[8, 0] == label[1, 0]  # wraps around


def test_parabolic_peak_refinement():
    resp = torch.tensor([[0.0, 0.0, 0.0], [0.0, 1.0, 0.5], [0.0, 0.0, 0.0]])
    row, col, value = response_peak(resp, circular=False)
    assert (row, value) == (1.0, 1.0) and 1.0 < col < 1.5


def test_dcf_recovers_a_circular_shift():
    gen = torch.Generator().manual_seed(0)
    x = torch.randn(1, 8, 32, 32, generator=gen)
    head = DCFHead(BoxPropagationConfig(context=4.5))
    head.init(x)
    for shift in [(0, 0), (3, -5), (-7, 2)]:
        z = torch.roll(x, shifts=shift, dims=(2, 3))
        row, col, _ = response_peak(head.respond(z)[0], circular=True)
        dy, dx = head.displacement(row, col, 32)
        assert (dy, dx) == pytest.approx(shift, abs=0.05)
    # The trained filter reproduces the Gaussian label on its own sample.
    torch.testing.assert_close(head.respond(x)[0], gaussian_label(32, 32 / 4.5 * 0.1),
                               atol=1e-3, rtol=0)


def test_xcorr_recovers_a_shift():
    gen = torch.Generator().manual_seed(1)
    big = torch.randn(1, 8, 50, 50, generator=gen)
    x = big[:, :, 10:40, 10:40]
    head = XCorrHead(BoxPropagationConfig(template_size=8))
    head.init(x)
    z = big[:, :, 7:37, 14:44]  # the content moves by (+3, -4)
    row, col, _ = response_peak(head.respond(z)[0], circular=False)
    assert head.displacement(row, col, 30) == pytest.approx((3, -4), abs=0.05)


def pooled_features(crops: np.ndarray) -> torch.Tensor:
    """Stride-8 'features': 8 x 8 average pooling of the crops, zero-mean per map."""
    x = torch.from_numpy(crops).permute(0, 3, 1, 2).float() / 255.0
    feats = F.avg_pool2d(x, 8)
    return feats - feats.mean(dim=(2, 3), keepdim=True)


def textured_image(shift: tuple[int, int], size: int = 400) -> np.ndarray:
    rng = np.random.default_rng(7)
    base = rng.integers(0, 255, (size // 8, size // 8, 3), dtype=np.uint8)
    image = np.kron(base, np.ones((8, 8, 1), np.uint8))
    image = np.roll(image, shift, axis=(0, 1))
    return image


@pytest.mark.parametrize("method", ["dcf", "xcorr"])
def test_tracker_follows_a_known_motion_with_the_exact_displacement_scale(method):
    cfg = BoxPropagationConfig(method=method, crop_size=160, num_scales=1, subpixel=True)
    tracker = BoxPropagator(pooled_features, cfg, stride=8)
    start = BoxState(200.0, 200.0, 40.0, 40.0)  # window 180 px -> 180 / 20 px per feature
    tracker.reset(textured_image((0, 0)), start)
    state = tracker.step(textured_image((18, -27)))  # two and three feature pixels
    # window/52 (the authors' scale) would move it 25% too far: (22.5, -33.75).
    assert (state.cy - 200.0, state.cx - 200.0) == pytest.approx((18.0, -27.0), abs=1.5)
    assert (state.w, state.h) == (40.0, 40.0)


def test_scale_choice_and_size_clamp():
    def flat(crops: np.ndarray) -> torch.Tensor:  # identical responses at every scale
        return torch.ones(len(crops), 2, 4, 4)

    cfg = BoxPropagationConfig(method="xcorr", crop_size=32, template_size=2,
                               scale_step=2.0, min_size_factor=0.9, feature_window=False)
    tracker = BoxPropagator(flat, cfg)
    tracker.reset(np.zeros((64, 64, 3), np.uint8), BoxState(32, 32, 10, 10))
    state = tracker.step(np.zeros((64, 64, 3), np.uint8))
    assert (state.w, state.h) == (10.0, 10.0)  # penalties break the tie for scale 1
    assert tracker.last_scores[1] > tracker.last_scores[0]
    tracker.reset(np.zeros((64, 64, 3), np.uint8), BoxState(32, 32, 10, 10))
    tracker.head.respond = lambda feats: torch.stack(  # type: ignore[method-assign]
        [torch.full((3, 3), v) for v in (5.0, 1.0, 1.0)])
    state = tracker.step(np.zeros((64, 64, 3), np.uint8))
    assert (state.w, state.h) == (9.0, 9.0)  # halved, clamped to 0.9 x initial


def moving_patch_image(offset: tuple[int, int], size: int = 400) -> np.ndarray:
    """A static textured background with a 40-px textured target at (180, 180) + offset."""
    rng = np.random.default_rng(3)
    background = np.kron(rng.integers(0, 255, (size // 8, size // 8, 3), dtype=np.uint8),
                         np.ones((8, 8, 1), np.uint8))
    target = np.kron(rng.integers(0, 255, (5, 5, 3), dtype=np.uint8),
                     np.ones((8, 8, 1), np.uint8))
    image = background.copy()
    y, x = 180 + offset[0], 180 + offset[1]
    image[y:y + 40, x:x + 40] = target
    return image


def test_dcf_template_window_makes_the_filter_follow_the_target_not_the_background():
    def track(template_window: float | None) -> BoxState:
        cfg = BoxPropagationConfig(method="dcf", crop_size=160, num_scales=1,
                                   template_window=template_window, dcf_interp=0.0)
        tracker = BoxPropagator(pooled_features, cfg, stride=8)
        tracker.reset(moving_patch_image((0, 0)), BoxState(200.0, 200.0, 40.0, 40.0))
        for k in range(1, 4):
            state = tracker.step(moving_patch_image((8 * k, -8 * k)))
        return state

    windowed = track(1.5)
    assert (windowed.cy, windowed.cx) == pytest.approx((224.0, 176.0), abs=3.0)
    crop_wide = track(None)  # trained on 95% background: stays with the background
    assert abs(crop_wide.cy - 224.0) + abs(crop_wide.cx - 176.0) > 10.0


def test_dcf_update_crop_shares_the_next_frames_backbone_call():
    calls: list[int] = []

    def counted(crops: np.ndarray) -> torch.Tensor:
        calls.append(len(crops))
        return pooled_features(crops)

    cfg = BoxPropagationConfig(method="dcf", crop_size=160, dcf_interp=0.2)
    batched = BoxPropagator(counted, cfg, stride=8)
    eager = BoxPropagator(pooled_features, cfg, stride=8)  # update run right after its step
    start = BoxState(200.0, 200.0, 40.0, 40.0)
    for tracker in (batched, eager):
        tracker.reset(moving_patch_image((0, 0)), start)
    calls.clear()
    for t in range(1, 6):
        image = moving_patch_image((3 * t, -2 * t))
        got, want = batched.step(image), eager.step(image)
        pending = eager._pending_update
        eager._pending_update = None
        eager.head.update(eager._features(pending, template=True))
        assert (got.cx, got.cy, got.w, got.h) == pytest.approx(
            (want.cx, want.cy, want.w, want.h), abs=1e-4)
    assert calls == [3, 4, 4, 4, 4]  # one backbone call per frame
