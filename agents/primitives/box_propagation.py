"""Box propagation (UniTrack level 2, SOT): Siamese cross-correlation and a correlation filter.

UniTrack (Wang et al., NeurIPS 2021), section 2.3 and appendix B.1, propagates a box with
the shared appearance model ``phi`` in one of two ways:

* **XCorr** (SiamFC, Bertinetto et al. 2016): the response map is the cross-correlation of
  a template (the central ``14 x 14`` of the first frame's crop features; never updated)
  with the search features, ``g = x * z``.
* **DCF** (DCFNet, Wang et al. 2017; CFNet): the template is replaced by the ridge-regression
  filter ``w = argmin ||w * x - y||^2 + lambda ||w||^2`` solved in the Fourier domain,
  ``w^ = x^ . y^* / (x^ . x^* + lambda)``, with a Gaussian ideal response ``y``; numerator
  and denominator are updated online by a moving average with momentum ``alpha``.

Common machinery (appendix B.1 table; ``OFFICIAL-CODE-FACTS.md``, "Box propagation"): crops
of ``context = 4.5`` times the target's width and height, resized to ``520 x 520`` (a
``65 x 65`` map at stride 8), padded with the image's mean colour (:func:`crop_windows`); a
Hann window on the crop features (suppresses the crop border and DCF's circular artefacts),
while the DCF filter is trained under a tighter window of 1.5 target sizes
(``DCF_TEMPLATE_WINDOW``) so that it describes the target, not its context; 3 scales
``1.0275^{-1, 0, 1}`` with peak penalties ``0.985^{1, 0, 1}``, the box size clamped to
``[0.2, 5] x`` the initial one; the peak's displacement (:func:`response_peak`, sub-pixel)
converted with ``window / 65`` image pixels per feature pixel. (The authors' code divides by
52 instead of 65, moving the box 25% too far; we use the exact scale.)

One module: the propagator (:class:`BoxPropagator`, :class:`BoxPropagationConfig`) and the
pieces it drives (crops, windows, the :class:`XCorrHead` and :class:`DCFHead` response
heads, the peak). Boxes are ``(cx, cy, w, h)`` in continuous image coordinates where pixel
``(i, j)`` (0-based row, column) covers ``[j, j + 1) x [i, i + 1)``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F


def _axis_taps(
    first: float, step: float, count: int, length: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Bilinear taps of ``count`` samples along one axis, over the pixels they read.

    Sample ``k`` at pixel-centre coordinate ``first + k * step`` (pixel ``j``'s centre at
    ``j``) blends pixels ``lo`` and ``lo + 1`` with weights ``1 - frac`` and ``frac``.
    Returns the pixels read (sorted, possibly outside ``[0, length)``), whether each is in
    the image, each sample's two taps as indices into those pixels, and ``frac``.
    """
    pos = first + step * np.arange(count, dtype=np.float64)
    lo = np.floor(pos)
    frac = pos - lo
    taps = lo.astype(np.int64)[:, None] + np.array([0, 1])
    read = np.unique(taps)
    inside = (read >= 0) & (read < length)
    return read, inside, np.searchsorted(read, taps), frac


def crop_windows(
    image: np.ndarray,
    centre: tuple[float, float],
    windows: np.ndarray,
    out_size: int,
    *,
    fill: tuple[float, float, float] | None = None,
) -> np.ndarray:
    """Crop axis-aligned windows around one centre and resize each to ``out_size`` squared.

    Exact bilinear sampling (positions in float64, values in float32), returned unrounded: a
    crop is a continuous function of the box. (Integer resamplers such as ``cv2.warpAffine``
    put sample positions on a 1/32-pixel grid and round the output to uint8, so a box moved by
    1e-6 px, float noise of the previous step, changes whole grey levels of the next crop; a
    tracker then carries that input-sized change on. ``benchmarks/sot_stability.py`` measures it.)

    Args:
        image: uint8 RGB ``(H, W, 3)``.
        centre: ``(cx, cy)`` in continuous coordinates (pixel ``j`` covers ``[j, j + 1)``).
        windows: ``(n, 2)`` window ``(width, height)`` in image pixels.
        out_size: Side of the output crops.
        fill: Colour outside the image (default: the image's mean colour, as SiamFC).

    Returns:
        ``(n, out_size, out_size, 3)`` float32 crops, pixel values in ``[0, 255]``; output
        pixel ``u`` samples image position ``c + (u + 0.5 - out_size / 2) * window / out_size``
        and a tap outside the image reads ``fill``.
    """
    height, width = image.shape[:2]
    if fill is None:  # an exact integer sum: the same colour on every machine
        fill = image.reshape(-1, 3).sum(0, dtype=np.int64) / (height * width)
    colour = np.asarray(fill, dtype=np.float64).reshape(3).astype(np.float32)
    cx, cy = centre
    crops = np.empty((len(np.reshape(windows, (-1, 2))), out_size, out_size, 3), np.float32)
    for i, (win_w, win_h) in enumerate(np.asarray(windows, dtype=np.float64).reshape(-1, 2)):
        ax, ay = win_w / out_size, win_h / out_size
        # Pixel-centre coordinates: continuous position minus 0.5.
        rows, in_y, ty, wy = _axis_taps(cy + (0.5 - out_size / 2) * ay - 0.5, ay,
                                        out_size, height)
        cols, in_x, tx, wx = _axis_taps(cx + (0.5 - out_size / 2) * ax - 0.5, ax,
                                        out_size, width)
        # The pixels the crop reads; those outside the image read the fill colour.
        block = np.empty((len(rows), len(cols), 3), np.float32)
        block[...] = colour
        block[np.ix_(in_y, in_x)] = image[np.ix_(rows[in_y], cols[in_x])]
        # Rows then columns, each ``a + frac * (b - a)`` in float32 elementwise (positions and
        # fractions in float64): IEEE-exact on every machine (no BLAS, no FMA), and exactly
        # the image's pixels at integer positions.
        top = block[ty[:, 0]]
        blended = top + wy[:, None, None].astype(np.float32) * (block[ty[:, 1]] - top)
        left = blended[:, tx[:, 0]]
        crops[i] = left + wx[None, :, None].astype(np.float32) * (blended[:, tx[:, 1]] - left)
    return crops


def hann_window(size: int) -> torch.Tensor:
    """``(size, size)`` symmetric 2-D Hann window (zero at the border, 1 at the centre)."""
    if size == 1:
        return torch.ones(1, 1)
    window = torch.hann_window(size, periodic=False, dtype=torch.float64).float()
    return torch.outer(window, window)


def gaussian_label(size: int, sigma: float) -> torch.Tensor:
    """``(size, size)`` Gaussian peaked at index ``(0, 0)``, wrapped circularly (DCF label)."""
    offsets = torch.arange(size, dtype=torch.float64)
    offsets = torch.where(offsets > size // 2, offsets - size, offsets)
    g = torch.exp(-0.5 * (offsets / sigma) ** 2)
    return torch.outer(g, g).float()


def _parabola(left: float, centre: float, right: float) -> float:
    """Offset in ``[-0.5, 0.5]`` of the vertex of the parabola through three samples."""
    denominator = left - 2.0 * centre + right
    if not denominator < 0:  # not a strict maximum: no refinement
        return 0.0
    return float(np.clip(0.5 * (left - right) / denominator, -0.5, 0.5))


def response_peak(response: torch.Tensor, *, circular: bool,
                  subpixel: bool = True) -> tuple[float, float, float]:
    """Location ``(row, col)`` and value of the maximum of a 2-D response map.

    Args:
        response: ``(h, w)`` map.
        circular: Neighbours wrap around (DCF responses are circular).
        subpixel: Refine each axis with a parabola through the peak and its neighbours
            (skipped at the border of a non-circular map).
    """
    h, w = response.shape
    flat = int(torch.argmax(response))
    row, col = divmod(flat, w)
    value = float(response[row, col])
    r, c = float(row), float(col)
    if subpixel:
        res = response.double()
        if circular or 0 < row < h - 1:
            r += _parabola(float(res[(row - 1) % h, col]), value, float(res[(row + 1) % h, col]))
        if circular or 0 < col < w - 1:
            c += _parabola(float(res[row, (col - 1) % w]), value, float(res[row, (col + 1) % w]))
    return r, c, value


# ---------------------------------------------------------------------- response heads
class XCorrHead:
    """SiamFC cross-correlation with a fixed first-frame template."""

    def __init__(self, config: BoxPropagationConfig) -> None:
        self.config = config
        self.template: torch.Tensor | None = None
        self.start = 0

    def init(self, features: torch.Tensor) -> None:
        """Cut the central template from the first crop's ``(1, C, s, s)`` features."""
        size = features.shape[-1]
        # template_size is for the stride-8 map of the crop; other strides keep its extent.
        t = min(max(1, round(self.config.template_size * size
                             / math.ceil(self.config.crop_size / 8))), size)
        self.start = (size - t) // 2
        self.template = features[:, :, self.start:self.start + t,
                                 self.start:self.start + t].contiguous()

    def respond(self, features: torch.Tensor) -> torch.Tensor:
        """``(n, s - t + 1, s - t + 1)`` responses of the search features ``(n, C, s, s)``."""
        if self.template is None:
            raise RuntimeError("XCorrHead.init() must be called first")
        return F.conv2d(features, self.template)[:, 0]

    def displacement(self, row: float, col: float, size: int) -> tuple[float, float]:
        """Feature-pixel shift ``(dy, dx)`` of the target for a peak at ``(row, col)``.

        A peak at ``p`` means the template (cut at ``start``) matches ``p - start`` feature
        pixels away from where it was cut.
        """
        return row - self.start, col - self.start

    def update(self, features: torch.Tensor) -> None:
        """XCorr never updates its template (every frame is compared with the first)."""

    circular = False


class DCFHead:
    """DCFNet-style correlation filter (linear kernel, multi-channel ridge regression).

    With ``X_c`` the DFT of feature channel ``c`` and ``Y`` the DFT of the Gaussian label, the
    filter that makes ``sum_c H_c X_c`` closest to ``Y`` under ridge regularisation ``lambda``
    is ``H_c = Y conj(X_c) / (sum_k |X_k|^2 + lambda)`` (exact for one training sample, per
    frequency). The response to search features ``Z`` is ``IDFT(sum_c H_c Z_c)``. The
    numerator ``A_c = Y conj(X_c)`` and denominator ``B = sum_k |X_k|^2 + lambda`` are moving
    averages ``(1 - alpha) old + alpha new`` (paper, appendix B.1).
    """

    circular = True

    def __init__(self, config: BoxPropagationConfig) -> None:
        self.config = config
        self.numerator: torch.Tensor | None = None
        self.denominator: torch.Tensor | None = None
        self._label_f: torch.Tensor | None = None

    def _terms(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        size = features.shape[-1]
        if self._label_f is None or self._label_f.shape[-2] != size:
            sigma = size / self.config.context * self.config.dcf_sigma_factor
            label = gaussian_label(size, sigma).double().to(features.device)
            self._label_f = torch.fft.rfft2(label)  # complex128
        xf = torch.fft.rfft2(features[0].double())
        numerator = self._label_f * torch.conj(xf)
        denominator = (xf.real ** 2 + xf.imag ** 2).sum(0) + self.config.dcf_lambda
        return numerator, denominator

    def init(self, features: torch.Tensor) -> None:
        """Train the filter on the first crop's ``(1, C, s, s)`` (windowed) features."""
        self.numerator, self.denominator = self._terms(features)

    def update(self, features: torch.Tensor) -> None:
        """Moving-average update with the crop at the new target position."""
        alpha = self.config.dcf_interp
        if alpha == 0 or self.numerator is None or self.denominator is None:
            return
        numerator, denominator = self._terms(features)
        self.numerator = (1 - alpha) * self.numerator + alpha * numerator
        self.denominator = (1 - alpha) * self.denominator + alpha * denominator

    def respond(self, features: torch.Tensor) -> torch.Tensor:
        """``(n, s, s)`` circular responses of the search features ``(n, C, s, s)``."""
        if self.numerator is None or self.denominator is None:
            raise RuntimeError("DCFHead.init() must be called first")
        size = features.shape[-1]
        zf = torch.fft.rfft2(features.double())
        filt = self.numerator / self.denominator
        return torch.fft.irfft2((filt.unsqueeze(0) * zf).sum(1), s=(size, size)).float()

    @staticmethod
    def displacement(row: float, col: float, size: int) -> tuple[float, float]:
        """Circular peak position -> signed shift (the label peaks at index 0)."""
        dy = row - size if row > size / 2 else row
        dx = col - size if col > size / 2 else col
        return dy, dx


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
"""``(n, S, S, 3)`` float32 crops (pixel values 0..255) -> ``(n, C, s, s)`` features (one
batched backbone pass)."""


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
        features: Callable turning a batch of float32 crops (pixel values) into feature maps.
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
