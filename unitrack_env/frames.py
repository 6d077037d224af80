"""Frame decoding with one-frame-ahead prefetching.

OpenCV releases the GIL while it decodes, so decoding frame ``t + 1`` on a helper thread
while the agent works on frame ``t`` hides most of the decode time.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.errors import DataFormatError

#: OpenCV >= 4.11 decodes straight to RGB, which saves a full-frame colour conversion.
_IMREAD_RGB = getattr(cv2, "IMREAD_COLOR_RGB", None)


def read_rgb(path: str | Path) -> np.ndarray:
    """Decode an image file to a ``uint8`` RGB array.

    Raises:
        DataFormatError: the file is missing or not a decodable image.
    """
    path = Path(path)
    image = cv2.imread(str(path), _IMREAD_RGB if _IMREAD_RGB is not None else cv2.IMREAD_COLOR)
    if image is None:
        reason = "missing" if not path.exists() else "not a decodable image (corrupt or truncated?)"
        raise DataFormatError(path, reason)
    if _IMREAD_RGB is None:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    return image


class FramePrefetcher:
    """Loads frames by index, decoding the next index in the background.

    Args:
        path_of: maps a frame index to its image file.
        prefetch: decode ``index + 1`` on a background thread after each request.
    """

    def __init__(self, path_of: Callable[[int], Path], *, prefetch: bool = True) -> None:
        self._path_of = path_of
        self._prefetch = prefetch
        self._executor: ThreadPoolExecutor | None = None
        self._pending: tuple[int, Future[np.ndarray]] | None = None

    def get(self, index: int) -> np.ndarray:
        """Return frame ``index`` as a fresh ``uint8`` RGB array."""
        image = None
        if self._pending is not None:
            pending_index, future = self._pending
            self._pending = None
            if pending_index == index:
                image = future.result()  # re-raises the decode error, if any
            else:
                future.cancel()
        if image is None:
            image = read_rgb(self._path_of(index))
        return image

    def schedule(self, index: int) -> None:
        """Start decoding ``index`` in the background (no-op when prefetching is off)."""
        if not self._prefetch:
            return
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="unitrack-frames")
        self._pending = (index, self._executor.submit(read_rgb, self._path_of(index)))

    def close(self) -> None:
        """Stop the background thread."""
        if self._pending is not None:
            self._pending[1].cancel()
            self._pending = None
        if self._executor is not None:
            self._executor.shutdown(wait=True)
            self._executor = None

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_executor"] = None
        state["_pending"] = None
        return state
