"""Single object tracking files shared by the OTB, LaSOT and GOT-10k readers.

Boxes stay as written (1-based pixels) so results written back round-trip to the official
files. Frames are images with numeric stems (``0001.jpg``, ``00000001.jpg``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.datasets.limits import (
    MAX_TEXT_BYTES,
    check_image_size,
    check_measured_image,
    image_size,
    read_limited,
)
from unitrack_env.errors import DataFormatError

IMAGE_EXTENSIONS: tuple[str, ...] = (".jpg", ".jpeg", ".png", ".bmp")
"""Frame file extensions recognised in image folders."""

#: Separators of box and flag files: commas and white space, in any mix.
_SEPARATORS = re.compile(r"[,\s]+")
#: The four values of a box row, as errors name them.
BOX_FIELDS = ("x", "y", "w", "h")


@dataclass(frozen=True)
class SOTSequence:
    """One single-object sequence: frames and the target's boxes.

    ``boxes`` are ``(x, y, w, h)`` as written (1-based); NaN rows have no annotation and OTB
    marks an absent target with a non-positive box. ``absent`` holds the benchmark's
    not-visible flags (all False for OTB); ``image_size`` is the first frame's ``(w, h)``;
    ``description`` the target's sentence where the benchmark has one (LaSOT's ``nlp.txt``).
    """

    name: str
    frame_paths: tuple[Path, ...]
    frame_numbers: tuple[int, ...]
    boxes: np.ndarray
    image_size: tuple[int, int]
    absent: np.ndarray
    benchmark: str
    description: str = ""

    def __post_init__(self) -> None:
        n = len(self.frame_paths)
        if self.boxes.shape != (n, 4) or self.absent.shape != (n,) or len(
            self.frame_numbers) != n:
            raise ValueError(f"{self.name}: frames, boxes and flags disagree in length")
        self.boxes.setflags(write=False)
        self.absent.setflags(write=False)

    @property
    def num_frames(self) -> int:
        """Number of frames of the sequence."""
        return len(self.frame_paths)

    @property
    def init_box(self) -> np.ndarray:
        """The target's box in the first frame (what a tracker is given)."""
        return self.boxes[0]

    @property
    def has_ground_truth(self) -> bool:
        """Whether frames after the first are annotated (False on GOT-10k test)."""
        return bool(np.isfinite(self.boxes[1:]).any()) if self.num_frames > 1 else True


def read_image_size(path: str | Path) -> tuple[int, int]:
    """Return ``(width, height)`` of an image file.

    Measured from the header (a decompression bomb is refused); a format whose header gives
    no size is refused before decoding. A missing, too large or undecodable file raises
    DataFormatError.
    """
    _, size = image_size(path)
    if size is not None and min(size) > 0:
        check_image_size(path, size)
        return size
    check_measured_image(path)
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise DataFormatError(path, "missing or not a readable image")
    return int(image.shape[1]), int(image.shape[0])


def read_box_file(path: str | Path, *, allow_nan: bool = True) -> np.ndarray:
    """Read an ``x,y,w,h`` box file with comma, tab or space separators (any mix).

    ``allow_nan`` accepts LaSOT/UAV's NaN rows. A line without exactly four numbers, or a
    blank line followed by more data (it would shift later frames), raises DataFormatError.
    """
    path = Path(path)
    try:
        text = read_limited(path, MAX_TEXT_BYTES, "box file").decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise DataFormatError(path, f"cannot read box file ({err})") from err
    rows: list[list[float]] = []
    blank_at: int | None = None
    for number, line in enumerate(text.splitlines(), start=1):
        content = line.strip().strip(",")
        if not content:
            blank_at = blank_at or number
            continue
        if blank_at is not None:
            raise DataFormatError(path, "blank line inside the box list", line=blank_at)
        parts = _SEPARATORS.split(content)
        if len(parts) != 4:
            raise DataFormatError(
                path, f"expected 4 numbers x,y,w,h, found {len(parts)}: {content!r}", line=number
            )
        values = []
        for field_name, part in zip(BOX_FIELDS, parts, strict=True):
            try:
                value = float(part)
            except ValueError:
                raise DataFormatError(
                    path, f"not a number: {part!r}", line=number, field=field_name
                ) from None
            if np.isinf(value) or (np.isnan(value) and not allow_nan):
                raise DataFormatError(path, f"invalid value {part!r}", line=number,
                                      field=field_name)
            values.append(value)
        rows.append(values)
    if not rows:
        raise DataFormatError(path, "contains no boxes")
    return np.asarray(rows, dtype=np.float64)


def read_flags(path: Path, expected: int) -> np.ndarray:
    """Read 0/1 flags written one per line or comma-separated on one line."""
    try:
        tokens = [t for t in _SEPARATORS.split(path.read_text(encoding="utf-8-sig")) if t]
    except OSError as err:
        raise DataFormatError(path, f"cannot read flag file ({err})") from err
    if len(tokens) != expected:
        raise DataFormatError(path, f"has {len(tokens)} flags, expected {expected} (one per frame)")
    try:
        values = np.array([int(float(t)) for t in tokens])
    except ValueError as err:
        raise DataFormatError(path, f"flags must be 0 or 1 ({err})") from None
    if not np.isin(values, (0, 1)).all():
        raise DataFormatError(path, "flags must be 0 or 1")
    return values.astype(bool)


def numbered_images(folder: Path) -> dict[int, Path]:
    """Map the integer stem of every image in ``folder`` to its path."""
    if not folder.is_dir():
        raise DataFormatError(folder, "image folder missing")
    images: dict[int, Path] = {}
    for p in folder.iterdir():
        if p.suffix.lower() in IMAGE_EXTENSIONS and p.stem.isdigit():
            images.setdefault(int(p.stem), p)
    if not images:
        kinds = ", ".join(IMAGE_EXTENSIONS)
        raise DataFormatError(folder, f"contains no numbered images ({kinds})")
    return images


def select_frames(folder: Path, numbers: range) -> tuple[Path, ...]:
    """The images of ``folder`` numbered ``numbers``; a missing one is an error."""
    images = numbered_images(folder)
    missing = [n for n in numbers if n not in images]
    if missing:
        raise DataFormatError(
            folder / f"{missing[0]:04d}.jpg",
            f"missing frame {missing[0]} ({len(missing)} of frames {numbers.start}-"
            f"{numbers.stop - 1} missing)",
        )
    return tuple(images[n] for n in numbers)

