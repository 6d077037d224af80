"""Frame decoding with one-frame-ahead prefetching.

OpenCV releases the GIL while it decodes, so decoding frame ``t + 1`` on a helper thread
while the agent works on frame ``t`` hides most of the decode time.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.datasets.limits import check_image_size, check_measured_image, header_size
from unitrack_env.errors import DataFormatError

#: OpenCV >= 4.11 decodes straight to RGB, which saves a full-frame colour conversion.
_IMREAD_RGB = getattr(cv2, "IMREAD_COLOR_RGB", None)

#: JPEG files end with the EOI marker; PNG files with the IEND chunk (type and CRC).
_JPEG_END = b"\xff\xd9"
_PNG_END = b"IEND\xaeB`\x82"
#: Bytes read from a file's end to find its end marker (encoders may pad after it).
_TAIL_BYTES = 64


def check_complete(path: str | Path) -> None:
    """Refuse a frame that is truncated, not an image, or a decompression bomb.

    libjpeg decodes a truncated JPEG silently, so the tail is checked (JPEG ``FF D9``, PNG
    ``IEND``). The format comes from the first bytes, not the name, like OpenCV; the header
    size is checked against :data:`~unitrack_env.datasets.limits.MAX_IMAGE_PIXELS` before
    decoding. Other suffixes get their size from the header too (TIFF, BMP, WebP, GIF, PNM),
    or are refused. Raises DataFormatError.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".jpg", ".jpeg", ".png"):
        check_measured_image(path)  # TIFF, BMP, WebP, ...: the size from the header, or refused
        return
    try:
        with path.open("rb") as handle:
            kind, size = header_size(handle)
            size_bytes = handle.seek(0, 2)
            handle.seek(max(0, size_bytes - _TAIL_BYTES))
            tail = handle.read()
    except FileNotFoundError:
        raise DataFormatError(path, "missing") from None
    except OSError as exc:
        raise DataFormatError(path, f"unreadable ({exc})") from None
    if size_bytes == 0:
        raise DataFormatError(path, "empty image file (0 bytes)")
    named = "PNG" if suffix == ".png" else "JPEG"
    if kind not in ("PNG", "JPEG"):
        what = f"a {kind} file" if kind else "not a JPEG or PNG image (unknown first bytes)"
        raise DataFormatError(path, f"{what} named {suffix}; convert it to {named}")
    check_image_size(path, size)
    marker, end = ((_JPEG_END, "JPEG end-of-image marker (FF D9)") if kind == "JPEG"
                   else (_PNG_END, "PNG IEND chunk"))
    if marker not in tail:
        really = f" (a {kind} file named {suffix})" if kind != named else ""
        raise DataFormatError(
            path, f"truncated image{really}: no {end} at the end of its {size_bytes} bytes; "
                  "the file was cut short (an interrupted copy or download); replace it with "
                  "a complete copy")


def read_rgb(path: str | Path) -> np.ndarray:
    """Decode an image file to a ``uint8`` RGB array (DataFormatError if missing or bad)."""
    path = Path(path)
    check_complete(path)
    image = cv2.imread(str(path), _IMREAD_RGB if _IMREAD_RGB is not None else cv2.IMREAD_COLOR)
    if image is None:
        reason = "missing" if not path.exists() else "not a decodable image (corrupt or truncated?)"
        raise DataFormatError(path, reason)
    if _IMREAD_RGB is None:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    return image


class FramePrefetcher:
    """Loads frames by index (``path_of``); with ``prefetch`` the next decodes in the background."""

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

    def check(self, indices: Iterable[int]) -> None:
        """Refuse (DataFormatError) a missing or truncated frame before any is decoded."""
        for index in indices:
            check_complete(self._path_of(index))

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
