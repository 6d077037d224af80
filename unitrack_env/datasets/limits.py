"""Limits checked at the door: image dimensions, id ranges and id counts.

Readers check their files against these limits when a sequence is opened, before the first
frame, so that a hostile or corrupt file is refused by name rather than exhausting memory
mid-episode or at scoring; each limit is far above the real benchmarks and far below what
memory holds. Images are measured from their header, undecoded: a 70-byte PNG can claim
100000x100000 pixels (Pillow refuses such a "decompression bomb", OpenCV allocates up to 1 Gpx
of it). Ids are int32, what the action space and the official result files carry exactly
(Python reads a JSON ``2**70`` as an int numpy cannot store). Track counts bound TrackEval's
HOTA, which keeps about 22 ``gt ids x tracker ids`` matrices of doubles per sequence
(``trackeval/metrics/hota.py``, 176 bytes per pair); the tracker's side is only known at
scoring, which checks the product against the machine's memory
(:func:`unitrack_env.metrics.motchallenge.check_matrix_memory`).
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from unitrack_env.errors import DataFormatError

#: Largest image (width x height) read as a frame or an annotation map: 8192 x 8192, about
#: eight times a 3840x2160 DAVIS Full-Resolution frame (the largest of any supported benchmark).
MAX_IMAGE_PIXELS = 8192 * 8192
#: Largest id read from an annotation file (int32).
MAX_ID = 2**31 - 1
#: Most distinct ground-truth ids (tracks, instances) in one sequence. The busiest
#: MOTChallenge sequence (MOT20-05) has about 1,200; 10,000 against 5,000 tracker ids
#: is 9 GB at scoring.
MAX_TRACKS = 10_000
#: Most frames in one sequence: 9 hours at 30 fps. The longest benchmark sequences have a
#: few thousand (MOT20-05 3,315; LaSOT's longest about 11,000); per-frame index arrays stay
#: at megabytes, where a ``seqLength`` of 10**11 asked for 745 GiB.
MAX_FRAMES = 1_000_000

#: Largest annotation text file (MOT/MOTS ground truth, detections and results, box files):
#: 256 MiB. Checked with ``stat`` (and a bounded read) before the file is read whole.
MAX_TEXT_BYTES = 256 * 2**20
#: Largest JSON file of one video (PoseTrack ground truth, detections, results): 64 MiB.
MAX_VIDEO_JSON_BYTES = 64 * 2**20
#: Largest JSON file of a whole split (YouTube-VIS): 1 GiB.
MAX_SPLIT_JSON_BYTES = 2**30

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_JPEG_MAGIC = b"\xff\xd8"  # start of image (SOI)
#: JPEG start-of-frame markers (SOF0..SOF15 but DHT C4, JPG C8 and DAC CC) hold the size.
_SOF_MARKERS = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
#: Other formats recognised from their first bytes, to name what a mis-named file really is.
_OTHER_MAGIC = ((b"GIF8", "GIF"), (b"BM", "BMP"), (b"II*\x00", "TIFF"), (b"MM\x00*", "TIFF"),
                (b"II+\x00", "BigTIFF"), (b"MM\x00+", "BigTIFF"), (b"RIFF", "WebP/RIFF"),
                *((f"P{i}".encode(), "PNM") for i in range(1, 7)))
#: Formats whose header size :func:`header_size` reads; frames in other formats are refused.
MEASURED_FORMATS = ("PNG", "JPEG", "TIFF", "BigTIFF", "BMP", "GIF", "WebP/RIFF", "PNM")


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


def _tiff_size(handle: Any, big: bool) -> tuple[int, int] | None:
    """ImageWidth (256) and ImageLength (257) of a TIFF's first image file directory."""
    handle.seek(0)
    head = handle.read(16)
    order = "little" if head[:2] == b"II" else "big"
    offset = int.from_bytes(head[8:16] if big else head[4:8], order)
    handle.seek(offset)
    count_bytes, entry, value_at = (8, 20, 12) if big else (2, 12, 8)
    count = int.from_bytes(handle.read(count_bytes), order)
    table = handle.read(min(count, 4096) * entry)
    found: dict[int, int] = {}
    for i in range(len(table) // entry):
        item = table[i * entry:(i + 1) * entry]
        tag, kind = int.from_bytes(item[0:2], order), int.from_bytes(item[2:4], order)
        if tag in (256, 257):  # SHORT (3) values sit first in the field, LONG (4) fill it
            width = 2 if kind == 3 else 8 if kind == 16 else 4
            found[tag] = int.from_bytes(item[value_at:value_at + width], order)
    return (found[256], found[257]) if len(found) == 2 else None


def _other_size(kind: str, handle: Any) -> tuple[int, int] | None:
    """``(width, height)`` from the header of a BMP, GIF, WebP, PNM or TIFF file."""
    if kind in ("TIFF", "BigTIFF"):
        return _tiff_size(handle, kind == "BigTIFF")
    handle.seek(0)
    head = handle.read(64)
    if kind == "BMP" and len(head) >= 26:
        if int.from_bytes(head[14:18], "little") == 12:  # OS/2 core header
            return int.from_bytes(head[18:20], "little"), int.from_bytes(head[20:22], "little")
        return (abs(int.from_bytes(head[18:22], "little", signed=True)),
                abs(int.from_bytes(head[22:26], "little", signed=True)))
    if kind == "GIF" and len(head) >= 10:
        return int.from_bytes(head[6:8], "little"), int.from_bytes(head[8:10], "little")
    if kind == "WebP/RIFF" and head[8:12] == b"WEBP" and len(head) >= 30:
        chunk = head[12:16]
        if chunk == b"VP8X":
            return (int.from_bytes(head[24:27], "little") + 1,
                    int.from_bytes(head[27:30], "little") + 1)
        if chunk == b"VP8L":
            bits = int.from_bytes(head[21:25], "little")
            return (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
        if chunk == b"VP8 ":
            return (int.from_bytes(head[26:28], "little") & 0x3FFF,
                    int.from_bytes(head[28:30], "little") & 0x3FFF)
        return None
    if kind == "PNM":
        handle.seek(2)
        text = b" ".join(line.split(b"#")[0] for line in handle.read(1024).splitlines())
        numbers = text.split()
        if len(numbers) >= 2 and numbers[0].isdigit() and numbers[1].isdigit():
            return int(numbers[0]), int(numbers[1])
    return None


def header_size(handle: BinaryIO) -> tuple[str | None, tuple[int, int] | None]:
    """:func:`image_size` of an open binary file (read from its start; position moves)."""
    handle.seek(0)
    kind = image_format(handle.read(8))
    if kind == "PNG":
        return kind, _png_size(handle)
    if kind == "JPEG":
        return kind, _jpeg_size(handle)
    if kind is not None:
        return kind, _other_size(kind, handle)
    return kind, None


def image_size(path: str | Path) -> tuple[str | None, tuple[int, int] | None]:
    """The format and ``(width, height)`` an image file's header states, not decoding.

    Formats: :data:`MEASURED_FORMATS`. Returns ``(format, None)`` for another format or an
    unreadable header.

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
    """Refuse an image whose header states an image too large to decode."""
    _, size = image_size(path)
    check_image_size(path, size)


def check_measured_image(path: str | Path) -> None:
    """Refuse an image whose size cannot be read from its header, or is too large.

    For frames in formats other than PNG and JPEG (TIFF, BMP, WebP, GIF, PNM): OpenCV would
    decode anything it knows, a 20000 x 20000 TIFF included, before a size could be checked.
    """
    kind, size = image_size(path)
    if kind not in MEASURED_FORMATS:
        formats = ", ".join(f.split("/")[0] for f in MEASURED_FORMATS)
        raise DataFormatError(
            path, f"not an image format whose size can be checked before decoding "
                  f"({kind or 'unknown first bytes'}); frames must be {formats}: convert it "
                  "to PNG or JPEG")
    if size is None:
        raise DataFormatError(path, f"{kind} header without a readable width and height "
                                    "(corrupt?); refused before decoding")
    check_image_size(path, size)


def read_limited(path: str | Path, limit: int, what: str) -> bytes:
    """The bytes of ``path`` if it holds at most ``limit`` (checked before it is read whole).

    The size is taken with ``stat`` and at most ``limit + 1`` bytes are read (so a file that
    grows, or a device, is refused too). Raises DataFormatError (also when missing).
    """
    path = Path(path)
    try:
        with path.open("rb") as handle:
            size = os.fstat(handle.fileno()).st_size
            data = handle.read(limit + 1) if size <= limit else b""
    except FileNotFoundError:
        raise DataFormatError(path, "missing") from None
    except OSError as exc:
        raise DataFormatError(path, f"unreadable ({exc})") from None
    if size > limit or len(data) > limit:
        shown = f"{size:,} bytes" if size > limit else f"more than {limit:,} bytes"
        cap = f"{limit / 2**20:,.0f} MiB" if limit >= 2**20 else f"{limit:,} bytes"
        raise DataFormatError(
            path, f"{shown}, more than the {cap} a {what} may hold "
                  "(unitrack_env.datasets.limits); refused before reading it: split it")
    return data


def load_json_limited(path: str | Path, limit: int, what: str) -> Any:
    """:func:`read_limited`, then :func:`json.loads` with the nesting depth bounded.

    JSON nested deeper than the parser's recursion limit (about 1,000 levels) is refused
    naming the file. Errors other than size and depth (not UTF-8, not JSON) propagate as
    ``UnicodeDecodeError`` / ``json.JSONDecodeError`` for the caller to name.
    """
    data = read_limited(path, limit, what)
    try:
        return json.loads(data.decode("utf-8"))
    except RecursionError:
        raise DataFormatError(
            path, f"JSON nested more than about {sys.getrecursionlimit():,} levels deep; no "
                  f"{what} nests past a few levels: not an annotation file") from None


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
