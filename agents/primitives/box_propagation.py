"""Box propagation (UniTrack level 2, SOT): Siamese cross-correlation and a correlation filter.

More in docs/module-notes.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from .box_response import (
    DCFHead,
    XCorrHead,
    crop_windows,
    hann_window,
    response_peak,
)

__all__ = [
    "CONTEXT",
    "CROP_SIZE",
    "DCF_INTERP",
    "DCF_LAMBDA",
    "DCF_SIGMA_FACTOR",
    "DCF_TEMPLATE_WINDOW",
    "MAX_SIZE_FACTOR",
    "METHODS",
    "MIN_SIZE_FACTOR",
    "NUM_SCALES",
    "SCALE_PENALTY",
    "SCALE_STEP",
    "XCORR_TEMPLATE_SIZE",
    "BoxPropagationConfig",
    "BoxPropagator",
    "BoxState",
    "FeatureFn",
    "feature_size",
]

CROP_SIZE: int = 520
"""Side of the square template/search crops in pixels (appendix B.1 text, and the authors'
code; the appendix table says 512, which would not give the stated 65 x 65 map)."""

CONTEXT: float = 4.5
"""Box expanding coefficient ``k``: the crop covers ``k`` times the target's width and height."""

NUM_SCALES: int = 3
"""Number of search scales ``s``."""

SCALE_STEP: float = 1.0275
"""Scale factors are ``SCALE_STEP ** i`` for ``i`` in ``-(s-1)/2 .. (s-1)/2``."""

SCALE_PENALTY: float = 0.985
"""The peak of scale ``i`` is penalised by ``SCALE_PENALTY ** |i|``."""

MIN_SIZE_FACTOR: float = 0.2
"""The box may not shrink below this fraction of the initial size (per axis)."""

MAX_SIZE_FACTOR: float = 5.0
"""The box may not grow beyond this multiple of the initial size (per axis)."""

XCORR_TEMPLATE_SIZE: int = 14
"""Side (feature pixels) of the XCorr template cut from the centre of the first crop's map
(the target spans ``65 / 4.5 = 14.4`` feature pixels)."""

DCF_LAMBDA: float = 1e-4
"""Ridge-regression regularisation ``lambda`` of the DCF head."""

DCF_INTERP: float = 1e-2
"""Online update momentum ``alpha`` of the DCF numerator and denominator."""

DCF_SIGMA_FACTOR: float = 0.1
"""Gaussian label sigma, as a fraction of the target's size in feature pixels
(``65 / 4.5 * 0.1 = 1.44`` feature pixels, DCFNet's ``output_sigma_factor``)."""

DCF_TEMPLATE_WINDOW: float | None = 1.5
"""Extent, in target sizes, of the Hann window on the DCF training features (None: the
crop-wide window). Not in the paper; the authors' code also trains the filter under a
separate "inner" window. With the crop-wide window the filter, trained on a crop that is
95% background, follows the background: on OTB Human3 (first 199 frames) AUC 0.04 -> 0.71
with 1.5 (1.0: 0.67, 2.0: 0.21); Crossing 0.78 either way (measured, imagenet-lite0)."""

METHODS: tuple[str, ...] = ("xcorr", "dcf")
"""Box propagation methods."""


@dataclass(frozen=True)
class BoxPropagationConfig:
    """Hyper-parameters of :class:`BoxPropagator` (defaults: the paper's appendix B.1).

    Attributes:
        method: ``"xcorr"`` or ``"dcf"``.
        crop_size: Side of the square crops (pixels).
        context: Crop extent in multiples of the target's width and height.
        num_scales: Number of search scales (odd).
        scale_step: Ratio between neighbouring scales.
        scale_penalty: Peak penalty per scale step away from 1.
        min_size_factor: Least box size, relative to the initial one.
        max_size_factor: Largest box size, relative to the initial one.
        feature_window: Multiply crop features by a Hann window.
        template_window: DCF only: the features the filter is trained on (first frame and
            updates) are multiplied by a Hann window covering this many target sizes around
            the centre instead of the whole crop (None: the crop-wide window).
        template_size: XCorr template side (feature pixels of the stride-8 map; a model of
            another stride cuts a template of the same extent in crop pixels).
        dcf_lambda: DCF regularisation.
        dcf_interp: DCF online update momentum (0: no update).
        dcf_sigma_factor: DCF Gaussian label sigma relative to the target size in features.
        subpixel: Refine the response peak with a parabola through its neighbours.
    """

    method: str = "dcf"
    crop_size: int = CROP_SIZE
    context: float = CONTEXT
    num_scales: int = NUM_SCALES
    scale_step: float = SCALE_STEP
    scale_penalty: float = SCALE_PENALTY
    min_size_factor: float = MIN_SIZE_FACTOR
    max_size_factor: float = MAX_SIZE_FACTOR
    feature_window: bool = True
    template_window: float | None = DCF_TEMPLATE_WINDOW
    template_size: int = XCORR_TEMPLATE_SIZE
    dcf_lambda: float = DCF_LAMBDA
    dcf_interp: float = DCF_INTERP
    dcf_sigma_factor: float = DCF_SIGMA_FACTOR
    subpixel: bool = True

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if self.crop_size < 8 or self.context <= 0:
            raise ValueError(f"crop_size must be >= 8 and context > 0 (got {self.crop_size}, "
                             f"{self.context})")
        if self.num_scales < 1 or self.num_scales % 2 == 0:
            raise ValueError(f"num_scales must be odd and >= 1, got {self.num_scales}")
        if not 0 < self.min_size_factor <= 1 <= self.max_size_factor:
            raise ValueError("need 0 < min_size_factor <= 1 <= max_size_factor")
        if self.template_window is not None and not self.template_window > 0:
            raise ValueError(f"template_window must be > 0 or None, got {self.template_window}")
        if not 0 <= self.dcf_interp <= 1 or self.dcf_lambda < 0:
            raise ValueError("need 0 <= dcf_interp <= 1 and dcf_lambda >= 0")

    def scale_factors(self) -> np.ndarray:
        """The search scales, e.g. ``[1/1.0275, 1, 1.0275]``."""
        half = (self.num_scales - 1) // 2
        return self.scale_step ** np.arange(-half, half + 1, dtype=np.float64)

    def scale_penalties(self) -> np.ndarray:
        """Peak multipliers of the scales, e.g. ``[0.985, 1, 0.985]``."""
        half = (self.num_scales - 1) // 2
        return self.scale_penalty ** np.abs(np.arange(-half, half + 1, dtype=np.float64))


# ---------------------------------------------------------------------- tracker
FeatureFn = Callable[[np.ndarray], torch.Tensor]
"""``(n, S, S, 3)`` uint8 crops -> ``(n, C, s, s)`` features (one batched backbone pass)."""


@dataclass
class BoxState:
    """The tracked box: centre and size in continuous image coordinates (pixels)."""

    cx: float
    cy: float
    w: float
    h: float


class BoxPropagator:
    """Propagate one box through a video with XCorr or DCF on stride-8 features.

    Args:
        features: Callable turning a batch of uint8 crops into feature maps.
        config: Hyper-parameters.
        stride: Pixels of the crop per feature pixel (the appearance model's stride).

    Attributes:
        state: The current box (None before :meth:`reset`).
        last_scores: Penalised peak of each scale in the last step (diagnostics).
    """

    def __init__(self, features: FeatureFn, config: BoxPropagationConfig | None = None,
                 *, stride: int = 8) -> None:
        self.features = features
        self.config = config or BoxPropagationConfig()
        self.stride = stride
        self.head: XCorrHead | DCFHead = (
            DCFHead(self.config) if self.config.method == "dcf" else XCorrHead(self.config)
        )
        self.state: BoxState | None = None
        self._pending_update: np.ndarray | None = None
        self._initial = (1.0, 1.0)
        self._window: torch.Tensor | None = None
        self.last_scores: np.ndarray = np.zeros(0)

    def _features(self, crops: np.ndarray, *, template: bool = False) -> torch.Tensor:
        return self._windowed(self.features(crops).float(), template=template)

    def _windowed(self, feats: torch.Tensor, *, template: bool = False) -> torch.Tensor:
        if template and self.config.method == "dcf" and self.config.template_window:
            return feats * self._template_window(feats.shape[-1]).to(feats.device)
        if self.config.feature_window:
            size = feats.shape[-1]
            if self._window is None or self._window.shape[-1] != size:
                self._window = hann_window(size).to(feats.device)
            feats = feats * self._window
        return feats

    def _template_window(self, size: int) -> torch.Tensor:
        """The DCF training window: Hann over ``template_window`` target sizes, 0 outside.

        The target spans ``size / context`` feature pixels of a ``size`` x ``size`` map.
        """
        side = min(size, max(1, round(size / self.config.context * self.config.template_window)))
        window = torch.zeros(size, size)
        start = (size - side) // 2
        window[start:start + side, start:start + side] = hann_window(side + 2)[1:-1, 1:-1]
        return window

    def _window_size(self, w: float, h: float) -> np.ndarray:
        return np.array([[w * self.config.context, h * self.config.context]])

    def reset(self, image: np.ndarray, box: BoxState) -> None:
        """Initialise on the first frame with the given box."""
        if not (box.w > 0 and box.h > 0):
            raise ValueError(f"the initial box must have a positive size, got {box}")
        self.state = BoxState(box.cx, box.cy, box.w, box.h)
        self._initial = (box.w, box.h)
        self._window = None
        self._pending_update = None
        crops = crop_windows(image, (box.cx, box.cy), self._window_size(box.w, box.h),
                             self.config.crop_size)
        self.head.init(self._features(crops, template=True))

    def step(self, image: np.ndarray) -> BoxState:
        """Locate the target in a new frame; returns (and keeps) the new box."""
        if self.state is None:
            raise RuntimeError("call reset(image, box) first")
        cfg = self.config
        st = self.state
        scales = cfg.scale_factors()
        windows = self._window_size(st.w, st.h) * scales[:, None]
        crops = crop_windows(image, (st.cx, st.cy), windows, cfg.crop_size)
        if self._pending_update is not None:
            # The previous frame's update crop shares this frame's backbone call; the filter
            # is updated before it responds, exactly as if the update had run last frame.
            batch = self.features(np.concatenate([self._pending_update, crops])).float()
            self._pending_update = None
            self.head.update(self._windowed(batch[:1], template=True))
            feats = self._windowed(batch[1:])
        else:
            feats = self._features(crops)
        responses = self.head.respond(feats)
        peaks = [response_peak(r, circular=self.head.circular, subpixel=cfg.subpixel)
                 for r in responses]
        values = np.array([p[2] for p in peaks])
        penalties = cfg.scale_penalties()
        # Penalise towards lower scores whatever the sign of the peak.
        scores = values - np.abs(values) * (1.0 - penalties)
        self.last_scores = scores
        best = int(np.argmax(scores))
        row, col, _ = peaks[best]
        dy, dx = self.head.displacement(row, col, feats.shape[-1])
        # One feature pixel = stride crop pixels = stride * window / crop_size image pixels.
        win_w, win_h = windows[best]
        height, width = image.shape[:2]
        cx = float(np.clip(st.cx + dx * self.stride * win_w / cfg.crop_size, 0, width))
        cy = float(np.clip(st.cy + dy * self.stride * win_h / cfg.crop_size, 0, height))
        w0, h0 = self._initial
        w = float(np.clip(st.w * scales[best], cfg.min_size_factor * w0,
                          cfg.max_size_factor * w0))
        h = float(np.clip(st.h * scales[best], cfg.min_size_factor * h0,
                          cfg.max_size_factor * h0))
        self.state = BoxState(cx, cy, w, h)
        if isinstance(self.head, DCFHead) and cfg.dcf_interp > 0:
            # Cropped now (this frame, the new box), run through the backbone with the next
            # frame's search crops: one backbone call per frame instead of two.
            self._pending_update = crop_windows(image, (cx, cy), self._window_size(w, h),
                                                cfg.crop_size)
        return self.state


def feature_size(crop_size: int, stride: int = 8) -> int:
    """Side of the feature map of a ``crop_size`` crop (``ceil(crop / stride)``)."""
    return math.ceil(crop_size / stride)
