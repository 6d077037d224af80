"""Response maps of box propagation: crops, windows, the XCorr and DCF heads, the peak.

:func:`crop_windows` cuts the scaled search windows out of a frame; a head
(:class:`XCorrHead` or :class:`DCFHead`) turns windowed crop features into a response map;
:func:`response_peak` finds its sub-pixel maximum. The tracker that drives them is
:class:`~unitrack_env.agents.primitives.box_propagation.BoxPropagator`; the method is
described in :mod:`unitrack_env.agents.primitives.box_propagation`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import cv2
import numpy as np
import torch
import torch.nn.functional as F

if TYPE_CHECKING:
    from .box_propagation import BoxPropagationConfig


def crop_windows(
    image: np.ndarray,
    centre: tuple[float, float],
    windows: np.ndarray,
    out_size: int,
    *,
    fill: tuple[float, float, float] | None = None,
) -> np.ndarray:
    """Crop axis-aligned windows around one centre and resize each to ``out_size`` squared.

    Args:
        image: uint8 RGB ``(H, W, 3)``.
        centre: ``(cx, cy)`` in continuous coordinates (pixel ``j`` covers ``[j, j + 1)``).
        windows: ``(n, 2)`` window ``(width, height)`` in image pixels.
        out_size: Side of the output crops.
        fill: Colour outside the image (default: the image's mean colour, as SiamFC).

    Returns:
        ``(n, out_size, out_size, 3)`` uint8 crops (bilinear sampling).
    """
    if fill is None:
        fill = tuple(float(v) for v in image.reshape(-1, 3).mean(0))
    cx, cy = centre
    crops = []
    for win_w, win_h in np.asarray(windows, dtype=np.float64).reshape(-1, 2):
        ax, ay = win_w / out_size, win_h / out_size
        # Output pixel u (centre u + 0.5) samples image position cx + (u + 0.5 - S/2) * a,
        # i.e. OpenCV coordinate (pixel centres at integers) that minus 0.5.
        matrix = np.array([
            [ax, 0.0, cx + (0.5 - out_size / 2) * ax - 0.5],
            [0.0, ay, cy + (0.5 - out_size / 2) * ay - 0.5],
        ])
        crops.append(cv2.warpAffine(
            image, matrix, (out_size, out_size),
            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
            borderMode=cv2.BORDER_CONSTANT, borderValue=fill,
        ))
    return np.stack(crops)


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


