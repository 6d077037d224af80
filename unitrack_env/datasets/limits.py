"""Limits checked at the door: image dimensions, id ranges and id counts.

More in docs/module-notes.md.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from unitrack_env.errors import DataFormatError

#: Largest image (width x height) read as a frame or an annotation map: 8192 x 8192.
MAX_IMAGE_PIXELS = 8192 * 8192
#: Largest id read from an annotation file (int32).
MAX_ID = 2**31 - 1
#: Most distinct ground-truth ids (tracks, instances) in one sequence.
MAX_TRACKS = 10_000
#: Most frames in one sequence: 9 hours at 30 fps. The longest benchmark sequences have a
#: few thousand (MOT20-05 3,315; LaSOT's longest about 11,000); per-frame index arrays stay
#: at megabytes, where a ``seqLength`` of 10**11 asked for 745 GiB.
MAX_FRAMES = 1_000_000

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_JPEG_MAGIC = b"\xff\xd8"  # start of image (SOI)
#: JPEG start-of-frame markers (SOF0..SOF15 but DHT C4, JPG C8 and DAC CC) hold the size.
_SOF_MARKERS = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
#: Other formats recognised from their first bytes, to name what a mis-named file really is.
_OTHER_MAGIC = ((b"GIF8", "GIF"), (b"BM", "BMP"), (b"II*\x00", "TIFF"), (b"MM\x00*", "TIFF"),
                (b"RIFF", "WebP/RIFF"))


def image_format(head: bytes) -> str | None:
    """``"PNG"``, ``"JPEG"`` or another format's name from a file's first bytes, or None."""
    if head.startswith(_PNG_MAGIC):
        return "PNG"
    if head.startswith(_JPEG_MAGIC):
        return "JPEG"
    return next((name for magic, name in _OTHER_MAGIC if head.startswith(magic)), None)


def _png_size(handle: Any) -> tuple[int, int] | None:
    handle.seek(8)
    chunk = handle.read(16)  # length (4), "IHDR", width (4), height (4)
    if len(chunk) < 16 or chunk[4:8] != b"IHDR":
        return None
    return int.from_bytes(chunk[8:12], "big"), int.from_bytes(chunk[12:16], "big")


def _jpeg_size(handle: Any) -> tuple[int, int] | None:
    handle.seek(2)
    while True:
        marker = handle.read(2)
        while len(marker) == 2 and marker[0] == 0xFF and marker[1] == 0xFF:  # fill bytes
            marker = marker[1:] + handle.read(1)
        if len(marker) < 2 or marker[0] != 0xFF or marker[1] in (0xD9, 0xDA):
            return None  # end of image or start of scan before a frame header
        if 0xD0 <= marker[1] <= 0xD7 or marker[1] == 0x01:
            continue  # markers without a length
        length = int.from_bytes(handle.read(2), "big")
        if length < 2:
            return None
        if marker[1] in _SOF_MARKERS:
            body = handle.read(5)  # precision (1), height (2), width (2)
            if len(body) < 5:
                return None
            return int.from_bytes(body[3:5], "big"), int.from_bytes(body[1:3], "big")
        handle.seek(length - 2, 1)


def header_size(handle: BinaryIO) -> tuple[str | None, tuple[int, int] | None]:
    """:func:`image_size` of an open binary file (read from its start; position moves)."""
    handle.seek(0)
    kind = image_format(handle.read(8))
    if kind == "PNG":
        return kind, _png_size(handle)
    if kind == "JPEG":
        return kind, _jpeg_size(handle)
    return kind, None


def image_size(path: str | Path) -> tuple[str | None, tuple[int, int] | None]:
    """The format and ``(width, height)`` a PNG or JPEG file's header states, not decoding.

    Returns ``(format, None)`` when the format is not PNG/JPEG or its header is unreadable.

    Raises:
        DataFormatError: the file is missing or unreadable.
    """
    path = Path(path)
    try:
        with path.open("rb") as handle:
            return header_size(handle)
    except FileNotFoundError:
        raise DataFormatError(path, "missing") from None
    except OSError as exc:
        raise DataFormatError(path, f"unreadable ({exc})") from None


def check_image_size(path: str | Path, size: tuple[int, int] | None, *,
                     field: str | None = None) -> None:
    """Refuse an image size of more than :data:`MAX_IMAGE_PIXELS` pixels.

    ``size`` is ``(width, height)`` from an image header or, with ``field``, from an
    annotation file's fields (e.g. a JSON video's width and height).
    """
    if size is None:
        return
    width, height = size
    if width * height > MAX_IMAGE_PIXELS:
        source = f"says {width}x{height}" if field else f"header says {width}x{height}"
        raise DataFormatError(
            path, f"{'it' if field else 'its'} {source} pixels, more than the "
                  f"{MAX_IMAGE_PIXELS:,} (8192x8192) no supported benchmark comes near (a "
                  "'decompression bomb' or a corrupt header); refused before decoding",
            field=field)


def check_image_header(path: str | Path) -> None:
    """Refuse a PNG or JPEG whose header states an image too large to decode."""
    _, size = image_size(path)
    check_image_size(path, size)


def check_id(value: Any, path: str | Path, *, field: str, line: int | None = None,
             low: int = 0, what: str = "id") -> int:
    """``value`` as an int after checking it is a whole number in ``low..MAX_ID``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise DataFormatError(path, f"{what} must be an integer, got {value!r}", line=line,
                              field=field)
    if isinstance(value, (float, np.floating)) and not float(value).is_integer():
        raise DataFormatError(path, f"{what} must be an integer, got {value!r}", line=line,
                              field=field)
    number = int(value)
    if not low <= number <= MAX_ID:
        raise DataFormatError(
            path, f"{what} {number} is out of range {low}..{MAX_ID} (int32, the ids the official "
                  "result files and scorers store exactly); renumber the ids",
            line=line, field=field)
    return number


def check_track_count(ids: Iterable[Any], path: str | Path, *, what: str = "ground-truth ids",
                      field: str | None = None) -> None:
    """Refuse a sequence with more than :data:`MAX_TRACKS` distinct ``ids``."""
    values = ids if isinstance(ids, np.ndarray) else list(ids)
    check_track_total(len(np.unique(np.asarray(values))) if len(values) else 0, path,
                      what=what, field=field)


def check_track_total(count: int, path: str | Path, *, what: str = "ground-truth ids",
                      field: str | None = None, line: int | None = None) -> None:
    """Refuse ``count`` tracks (distinct ``what``) in one sequence above :data:`MAX_TRACKS`."""
    if count > MAX_TRACKS:
        raise DataFormatError(
            path, f"{count:,} distinct {what} in one sequence, more than {MAX_TRACKS:,}: the "
                  "official scorer (TrackEval's HOTA) holds about 22 matrices of ground-truth x "
                  "tracker ids (at 10 million ids, 728 TiB each); the busiest real sequence "
                  "(MOT20-05) has about 1,200; split the sequence",
            line=line, field=field)
