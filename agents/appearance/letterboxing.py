"""The JDE-style letterbox: a frame resized with its aspect ratio kept, padded to a fixed size.

UniTrack's MOT head (following JDE) feeds the whole frame to the backbone letterboxed to
1088 x 608 (:data:`MOT_INPUT_SIZE`); :class:`Letterbox` keeps the scale and offset that map
boxes between the frame, the network input and the stride-8 feature map.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .architectures import FEATURE_STRIDE

MOT_INPUT_SIZE: tuple[int, int] = (1088, 608)
"""(width, height) that MOT frames are letterboxed to (JDE / UniTrack MOT setting)."""

LETTERBOX_PAD_VALUE: int = 128
"""Grey level of letterbox padding (JDE pads with 127.5; uint8 images round it to 128)."""


@dataclass(frozen=True)
class Letterbox:
    """A frame resized with its aspect ratio kept and padded to a fixed input size.

    ``scale`` ``(sx, sy)`` and ``offset`` ``(dx, dy)`` map frame pixels to input pixels;
    ``image`` is None for a geometry-only letterbox (:func:`letterbox_layout`).
    """

    image: np.ndarray | None
    scale: tuple[float, float]
    offset: tuple[int, int]
    original_size: tuple[int, int]

    def boxes_to_input(self, boxes_xyxy: np.ndarray) -> np.ndarray:
        """Map ``(n, 4)`` x1y1x2y2 boxes from frame pixels to letterboxed-input pixels."""
        boxes = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
        sx, sy = self.scale
        dx, dy = self.offset
        return boxes * np.array([sx, sy, sx, sy]) + np.array([dx, dy, dx, dy])

    def boxes_to_features(self, boxes_xyxy: np.ndarray, stride: int = FEATURE_STRIDE) -> np.ndarray:
        """Map frame-pixel x1y1x2y2 boxes to feature-map coordinates (input pixels / stride)."""
        return self.boxes_to_input(boxes_xyxy) / stride

    def boxes_to_frame(self, boxes_xyxy: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`boxes_to_input`."""
        boxes = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
        sx, sy = self.scale
        dx, dy = self.offset
        return (boxes - np.array([dx, dy, dx, dy])) / np.array([sx, sy, sx, sy])


def letterbox(
    image: np.ndarray,
    size: tuple[int, int] = MOT_INPUT_SIZE,
    *,
    pad_value: int = LETTERBOX_PAD_VALUE,
) -> Letterbox:
    """Resize ``image`` to fit ``size`` (width, height) keeping its aspect; pad the rest.

    The content is centred, as in JDE; area interpolation when shrinking, bilinear enlarging.
    """
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise ValueError(
            f"letterbox expects a uint8 RGB image (H, W, 3); got {image.dtype} {image.shape}"
        )
    layout = letterbox_layout(image.shape[0], image.shape[1], size)
    (width, height), (dx, dy) = layout.original_size, layout.offset
    new_w, new_h = round(layout.scale[0] * width), round(layout.scale[1] * height)
    interp = cv2.INTER_AREA if new_w < width else cv2.INTER_LINEAR
    resized = cv2.resize(image, (new_w, new_h), interpolation=interp)
    out = np.full((size[1], size[0], 3), pad_value, dtype=np.uint8)
    out[dy:dy + new_h, dx:dx + new_w] = resized
    return Letterbox(out, layout.scale, layout.offset, layout.original_size)


def letterbox_layout(height: int, width: int, size: tuple[int, int] = MOT_INPUT_SIZE) -> Letterbox:
    """The geometry of :func:`letterbox` for a ``height x width`` frame, without any pixels.

    Lets a feature-cache hit map boxes without resizing the frame.
    """
    target_w, target_h = size
    ratio = min(target_w / width, target_h / height)
    new_w = min(target_w, max(1, round(width * ratio)))
    new_h = min(target_h, max(1, round(height * ratio)))
    offset = ((target_w - new_w) // 2, (target_h - new_h) // 2)
    return Letterbox(None, (new_w / width, new_h / height), offset, (width, height))
