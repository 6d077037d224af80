"""Variable-size array spaces: frames, mask stacks and label maps.

Benchmarks mix frame sizes (MOT17: 1920x1080 and 640x480); resizing would change their
geometry and padding would waste memory, so frames keep their native size within bounds.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces


class Image(spaces.Space[np.ndarray]):
    """A ``uint8`` image ``(H, W, channels)`` of at most ``max_height`` x ``max_width``."""

    def __init__(
        self, max_height: int, max_width: int, channels: int = 3, seed: int | None = None
    ) -> None:
        if max_height < 1 or max_width < 1 or channels < 1:
            raise ValueError("Image space bounds must be positive")
        self.max_height = int(max_height)
        self.max_width = int(max_width)
        self.channels = int(channels)
        super().__init__(shape=None, dtype=np.uint8, seed=seed)

    @property
    def is_np_flattenable(self) -> bool:
        """Images of varying size cannot be flattened to one fixed vector."""
        return False

    def sample(self, mask: Any = None, probability: Any = None) -> np.ndarray:
        """Return a random image of random size within the bounds."""
        if mask is not None or probability is not None:
            raise NotImplementedError("Image.sample does not support masks")
        height = int(self.np_random.integers(1, min(self.max_height, 64) + 1))
        width = int(self.np_random.integers(1, min(self.max_width, 64) + 1))
        return self.np_random.integers(0, 256, (height, width, self.channels), dtype=np.uint8)

    def contains(self, x: Any) -> bool:
        """Whether ``x`` is a ``uint8`` image within the bounds."""
        return (
            isinstance(x, np.ndarray)
            and x.dtype == np.uint8
            and x.ndim == 3
            and x.shape[2] == self.channels
            and 1 <= x.shape[0] <= self.max_height
            and 1 <= x.shape[1] <= self.max_width
        )

    def __repr__(self) -> str:
        return (f"Image(max_height={self.max_height}, max_width={self.max_width}, "
                f"channels={self.channels})")

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Image)
            and other.max_height == self.max_height
            and other.max_width == self.max_width
            and other.channels == self.channels
        )

    def to_jsonable(self, sample_n: Sequence[np.ndarray]) -> list:
        """Convert a batch of images to lists."""
        return [image.tolist() for image in sample_n]

    def from_jsonable(self, sample_n: Sequence[Any]) -> list[np.ndarray]:
        """Convert lists back to images."""
        return [np.asarray(image, dtype=np.uint8) for image in sample_n]



class MaskStack(spaces.Space[np.ndarray]):
    """A ``bool`` stack of ``n`` binary masks ``(n, H, W)``, ``n`` and size variable.

    A stack, not a label map, since VIS detections may overlap; not padded, since a 1080p
    slot costs 2 MB per frame. Bounded by ``max_count`` and ``max_height`` x ``max_width``.
    """

    def __init__(
        self, max_count: int, max_height: int, max_width: int, seed: int | None = None
    ) -> None:
        if max_count < 0 or max_height < 1 or max_width < 1:
            raise ValueError("MaskStack bounds must be positive (max_count >= 0)")
        self.max_count = int(max_count)
        self.max_height = int(max_height)
        self.max_width = int(max_width)
        super().__init__(shape=None, dtype=np.bool_, seed=seed)

    @property
    def is_np_flattenable(self) -> bool:
        """Stacks of varying size cannot be flattened to one fixed vector."""
        return False

    def sample(self, mask: Any = None, probability: Any = None) -> np.ndarray:
        """Return random masks: a random count (at most 3) of a random size within the bounds."""
        if mask is not None or probability is not None:
            raise NotImplementedError("MaskStack.sample does not support masks")
        count = int(self.np_random.integers(0, min(self.max_count, 3) + 1))
        height = int(self.np_random.integers(1, min(self.max_height, 32) + 1))
        width = int(self.np_random.integers(1, min(self.max_width, 32) + 1))
        return self.np_random.integers(0, 2, (count, height, width)).astype(bool)

    def contains(self, x: Any) -> bool:
        """Whether ``x`` is a ``bool`` array ``(n, H, W)`` within the bounds."""
        return (
            isinstance(x, np.ndarray)
            and x.dtype == np.bool_
            and x.ndim == 3
            and 0 <= x.shape[0] <= self.max_count
            and 1 <= x.shape[1] <= self.max_height
            and 1 <= x.shape[2] <= self.max_width
        )

    def __repr__(self) -> str:
        return (f"MaskStack(max_count={self.max_count}, max_height={self.max_height}, "
                f"max_width={self.max_width})")

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, MaskStack)
            and other.max_count == self.max_count
            and other.max_height == self.max_height
            and other.max_width == self.max_width
        )

    def to_jsonable(self, sample_n: Sequence[np.ndarray]) -> list:
        """Convert a batch of mask stacks to lists."""
        return [masks.tolist() for masks in sample_n]

    def from_jsonable(self, sample_n: Sequence[Any]) -> list[np.ndarray]:
        """Convert lists back to mask stacks."""
        return [np.asarray(masks, dtype=bool) for masks in sample_n]


class LabelMap(spaces.Space[np.ndarray]):
    """A ``uint8`` label map ``(H, W)`` (0 = background, ``k`` = object ``k``, DAVIS 255 = void).

    Environments call :meth:`narrow` at every reset with the frame size and allowed labels, so
    :meth:`sample` draws valid actions; :meth:`contains` and equality depend on the bounds only.
    """

    def __init__(
        self, max_height: int, max_width: int, max_label: int = 255, seed: int | None = None
    ) -> None:
        if max_height < 1 or max_width < 1:
            raise ValueError("LabelMap space bounds must be positive")
        if not 0 <= max_label <= 255:
            raise ValueError(f"max_label must lie in 0..255 (uint8); got {max_label}")
        self.max_height = int(max_height)
        self.max_width = int(max_width)
        self.max_label = int(max_label)
        self._sample_shape: tuple[int, int] | None = None
        self._sample_labels: np.ndarray | None = None
        super().__init__(shape=None, dtype=np.uint8, seed=seed)

    @property
    def is_np_flattenable(self) -> bool:
        """Maps of varying size cannot be flattened to one fixed vector."""
        return False

    def narrow(self, height: int, width: int, labels: Sequence[int]) -> None:
        """Make :meth:`sample` draw ``(height, width)`` maps with values from ``labels``."""
        values = np.asarray(sorted({int(v) for v in labels}), dtype=np.uint8)
        if len(values) == 0 or int(values.max()) > self.max_label:
            raise ValueError(f"labels must be a non-empty subset of 0..{self.max_label}")
        if not (1 <= height <= self.max_height and 1 <= width <= self.max_width):
            raise ValueError(f"size {height}x{width} exceeds the space's bounds")
        self._sample_shape = (int(height), int(width))
        self._sample_labels = values

    def sample(self, mask: Any = None, probability: Any = None) -> np.ndarray:
        """Return a random label map (of the narrowed size and labels, see the class doc)."""
        if mask is not None or probability is not None:
            raise NotImplementedError("LabelMap.sample does not support masks")
        if self._sample_shape is None or self._sample_labels is None:
            height = int(self.np_random.integers(1, min(self.max_height, 64) + 1))
            width = int(self.np_random.integers(1, min(self.max_width, 64) + 1))
            return self.np_random.integers(0, self.max_label + 1, (height, width), dtype=np.uint8)
        index = self.np_random.integers(0, len(self._sample_labels), self._sample_shape)
        return self._sample_labels[index]

    def contains(self, x: Any) -> bool:
        """Whether ``x`` is a 2-D ``uint8`` map within the size and label bounds."""
        return (
            isinstance(x, np.ndarray)
            and x.dtype == np.uint8
            and x.ndim == 2
            and 1 <= x.shape[0] <= self.max_height
            and 1 <= x.shape[1] <= self.max_width
            and (x.size == 0 or int(x.max()) <= self.max_label)
        )

    def __repr__(self) -> str:
        return (f"LabelMap(max_height={self.max_height}, max_width={self.max_width}, "
                f"max_label={self.max_label})")

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, LabelMap)
            and other.max_height == self.max_height
            and other.max_width == self.max_width
            and other.max_label == self.max_label
        )

    def to_jsonable(self, sample_n: Sequence[np.ndarray]) -> list:
        """Convert a batch of label maps to lists."""
        return [labels.tolist() for labels in sample_n]

    def from_jsonable(self, sample_n: Sequence[Any]) -> list[np.ndarray]:
        """Convert lists back to label maps."""
        return [np.asarray(labels, dtype=np.uint8) for labels in sample_n]

