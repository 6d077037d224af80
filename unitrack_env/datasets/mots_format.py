"""The MOTS txt and png formats: mask rows in, mask rows out.

Format in :mod:`unitrack_env.datasets.mots` (``time_frame id class_id img_height img_width
rle`` lines, or 16-bit png instance maps); :class:`MaskAnnotations` holds the rows of one
file with their line numbers, so later checks can name the file and the line.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import cv2
import numpy as np

from unitrack_env.datasets.limits import (
    MAX_FRAMES,
    MAX_TEXT_BYTES,
    check_image_header,
    check_track_total,
    read_limited,
)
from unitrack_env.datasets.rle import check_rle, decode_masks, encode_masks
from unitrack_env.errors import DataFormatError

#: Class ids of the format.
CLASS_CAR = 1
CLASS_PEDESTRIAN = 2
CLASS_IGNORE = 10
#: Object id of ignore regions in the png format.
IGNORE_ID = 10000
#: Largest integer a float64 holds exactly (rows are built as float64 arrays).
_MAX_EXACT = 2**53
#: ``class_id = obj_id // ID_CLASS_DIVISOR`` in the png format.
ID_CLASS_DIVISOR = 1000
#: Class names (TrackEval's) and ids.
CLASS_IDS = MappingProxyType({"car": CLASS_CAR, "pedestrian": CLASS_PEDESTRIAN})
#: Valid class ids in txt files.
VALID_CLASSES = frozenset({CLASS_CAR, CLASS_PEDESTRIAN, CLASS_IGNORE})
#: Fields of a txt line (a 7th, ``score``, is allowed in detection files).
TXT_FIELDS = ("time_frame", "id", "class_id", "img_height", "img_width", "rle")
#: KITTI MOTS frame rate (KITTI's cameras run at 10 Hz).

@dataclass(frozen=True)
class MaskAnnotations:
    """Mask rows of a MOTS txt/png file (ground truth, detections or results).

    ``frames`` as in the file (MOTS20 1-based, KITTI 0-based); ``counts`` are COCO compressed
    RLE strings; ``scores`` 1.0 where the file has none; ``lines`` are 1-based source lines
    (0 for png); ``source`` is the file read (None in memory).
    """

    frames: np.ndarray
    ids: np.ndarray
    classes: np.ndarray
    heights: np.ndarray
    widths: np.ndarray
    counts: tuple[bytes, ...]
    scores: np.ndarray
    lines: np.ndarray
    source: Path | None = None
    _by_frame: dict[int, np.ndarray] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        order: dict[int, list[int]] = {}
        for i, t in enumerate(self.frames.tolist()):
            order.setdefault(int(t), []).append(i)
        self._by_frame.update({t: np.asarray(v, dtype=np.int64) for t, v in order.items()})

    def __len__(self) -> int:
        return len(self.frames)

    @staticmethod
    def empty(source: Path | None = None) -> MaskAnnotations:
        """An empty record."""
        z = np.zeros(0, dtype=np.int64)
        return MaskAnnotations(z, z, z, z, z, (), np.zeros(0), z, source)

    def rows(self, frame: int) -> np.ndarray:
        """Indices of the rows of ``frame`` (file numbering), in file order."""
        return self._by_frame.get(int(frame), np.zeros(0, dtype=np.int64))

    def select(self, keep: np.ndarray) -> MaskAnnotations:
        """Rows where the boolean ``keep`` is true (or the given indices), in that order."""
        idx = np.flatnonzero(keep) if np.asarray(keep).dtype == bool else np.asarray(keep)
        return MaskAnnotations(
            self.frames[idx], self.ids[idx], self.classes[idx], self.heights[idx],
            self.widths[idx], tuple(self.counts[i] for i in idx), self.scores[idx],
            self.lines[idx], self.source,
        )

    def rles(self, idx: Sequence[int] | np.ndarray) -> list[dict]:
        """Pycocotools RLE dicts of rows ``idx``."""
        return [{"size": [int(self.heights[i]), int(self.widths[i])], "counts": self.counts[i]}
                for i in np.asarray(idx, dtype=np.int64)]

    def decode(self, idx: Sequence[int] | np.ndarray, height: int, width: int) -> np.ndarray:
        """Decode rows ``idx`` of a ``height x width`` frame to ``(k, H, W)`` bool.

        A row of another size or a corrupt RLE raises DataFormatError naming file and line.
        """
        idx = np.asarray(idx, dtype=np.int64)
        for i in idx:
            if (self.heights[i], self.widths[i]) != (height, width):
                raise self._error(int(i), f"mask is {self.widths[i]}x{self.heights[i]} but the "
                                  f"frame is {width}x{height}", "img_height")
        try:
            return decode_masks([self.counts[i] for i in idx], height, width)
        except Warning:
            raise  # a warning the user's filters turned into an error is not a data error
        except Exception as exc:  # pycocotools raises bare exceptions on corrupt strings
            first = int(idx[0]) if len(idx) else 0
            raise self._error(first, f"cannot decode the RLE of this frame ({exc})", "rle") \
                from None

    def _error(self, i: int, message: str, fld: str | None) -> DataFormatError:
        line = int(self.lines[i]) if len(self.lines) and self.lines[i] > 0 else None
        return DataFormatError(self.source or Path("<memory>"), message, line=line, field=fld)


def _build(rows: list[tuple], counts: list[bytes], lines: list[int], source: Path | None
           ) -> MaskAnnotations:
    if not rows:
        return MaskAnnotations.empty(source)
    arr = np.asarray(rows, dtype=np.float64)
    return MaskAnnotations(
        frames=arr[:, 0].astype(np.int64), ids=arr[:, 1].astype(np.int64),
        classes=arr[:, 2].astype(np.int64), heights=arr[:, 3].astype(np.int64),
        widths=arr[:, 4].astype(np.int64), counts=tuple(counts), scores=arr[:, 5],
        lines=np.asarray(lines, dtype=np.int64), source=source,
    )


def parse_instances_txt(
    path: str | os.PathLike, *, allow_score: bool = False, text: str | None = None,
    max_ids: int | None = None,
) -> MaskAnnotations:
    """Read a MOTS txt file (``time_frame id class_id img_height img_width rle``).

    ``allow_score`` accepts a 7th field (detections); ``text`` is the content if already read;
    more than ``max_ids`` distinct ids are refused at that line. DataFormatError names the file,
    line and field of the first problem.
    """
    path = Path(path)
    if text is None:
        text = _read_text(path)
    rows: list[tuple] = []
    counts: list[bytes] = []
    lines: list[int] = []
    seen: set[int] = set()
    for lineno, line in enumerate(text.splitlines(), start=1):
        parts = line.split()
        if not parts:
            continue
        row, rle = _parse_line(path, lineno, parts, allow_score)
        if max_ids is not None:
            seen.add(row[1])
            if len(seen) > max_ids:
                check_track_total(len(seen), path, what="ids up to this line", field="id",
                                  line=lineno)
        rows.append(row)
        counts.append(rle)
        lines.append(lineno)
    return _build(rows, counts, lines, path)


def _read_text(path: Path) -> str:
    """A MOTS txt file's text; a missing or unreadable file is a :class:`DataFormatError`."""
    if not path.exists():
        raise DataFormatError(path, "file not found")
    try:
        return read_limited(path, MAX_TEXT_BYTES, "MOTS txt file").decode("ascii")
    except UnicodeDecodeError as exc:
        raise DataFormatError(path, f"cannot read MOTS txt file ({exc})") from None


def _parse_line(
    path: Path, lineno: int, parts: list[str], allow_score: bool
) -> tuple[tuple, bytes]:
    """Check one line's fields; return its row ``(t, id, class, h, w, score)`` and its RLE."""
    allowed = (6, 7) if allow_score else (6,)
    if len(parts) not in allowed:
        want = "6 or 7 (with a score)" if allow_score else "6"
        raise DataFormatError(path, f"expected {want} space-separated fields "
                              f"({' '.join(TXT_FIELDS)}), got {len(parts)}", line=lineno)
    values = []
    for col in range(5):
        try:
            values.append(int(parts[col]))
        except ValueError:
            raise DataFormatError(path, f"{parts[col]!r} is not an integer", line=lineno,
                                  field=TXT_FIELDS[col]) from None
    t, obj, cls, h, w = values
    if not -1 <= obj <= _MAX_EXACT:  # rows are stored as float64, then int64
        raise DataFormatError(path, f"id {obj} is out of range -1..2**53 (rows are read as "
                              "doubles, which hold integers exactly only up to 2**53)",
                              line=lineno, field="id")
    if not 0 <= t <= MAX_FRAMES:
        raise DataFormatError(path, f"time_frame {t} is out of range 0..{MAX_FRAMES:,}",
                              line=lineno, field="time_frame")
    if cls not in VALID_CLASSES:
        raise DataFormatError(path, f"class {cls} is not 1 (car), 2 (pedestrian) or 10 "
                              "(ignore)", line=lineno, field="class_id")
    if h < 1 or w < 1:
        raise DataFormatError(path, f"image size {h}x{w} must be positive", line=lineno,
                              field="img_height")
    score = _score(path, lineno, parts) if len(parts) == 7 else 1.0
    rle = parts[5].encode("ascii", errors="replace")
    problem = check_rle(rle, h, w)
    if problem is not None:
        raise DataFormatError(path, problem, line=lineno, field="rle")
    return (t, obj, cls, h, w, score), rle


def _score(path: Path, lineno: int, parts: list[str]) -> float:
    """The 7th field of a detection line: a finite detection score."""
    try:
        score = float(parts[6])
    except ValueError:
        raise DataFormatError(path, f"{parts[6]!r} is not a number", line=lineno,
                              field="score") from None
    if not np.isfinite(score):
        raise DataFormatError(path, "score is not finite", line=lineno, field="score")
    return score


def format_instances_txt(ann: MaskAnnotations, *, with_scores: bool = False) -> str:
    """Format records as MOTS txt lines (sorted by frame, then id as written)."""
    order = np.lexsort((ann.ids, ann.frames)) if len(ann) else np.zeros(0, np.int64)
    out = []
    for i in order:
        line = (f"{ann.frames[i]} {ann.ids[i]} {ann.classes[i]} {ann.heights[i]} "
                f"{ann.widths[i]} {ann.counts[i].decode('ascii')}")
        if with_scores:
            line += f" {ann.scores[i]:.5f}"
        out.append(line)
    return "".join(line + "\n" for line in out)


def read_instances_png(folder: str | os.PathLike) -> MaskAnnotations:
    """Read a folder of MOTS ``<frame>.png`` annotations (16-bit ids, ``class = id // 1000``).

    Raises DataFormatError for a missing or empty folder, a non-16-bit png or a bad name.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise DataFormatError(folder, "png annotation folder not found")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() == ".png")
    if not files:
        raise DataFormatError(folder, "contains no .png annotation files")
    rows: list[tuple] = []
    counts: list[bytes] = []
    for path in files:
        if not path.stem.isdigit():
            raise DataFormatError(path, "file name must be the frame number, e.g. 000000.png")
        check_image_header(path)
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise DataFormatError(path, "not a decodable png")
        if image.ndim != 2 or image.dtype != np.uint16:
            raise DataFormatError(path, f"expected a 16-bit single-channel png, got dtype "
                                  f"{image.dtype} and shape {image.shape}")
        ids = np.unique(image)
        ids = ids[ids > 0]
        masks = image[None] == ids[:, None, None]
        h, w = image.shape
        for obj, rle in zip(ids.tolist(), encode_masks(masks), strict=True):
            cls = CLASS_IGNORE if obj == IGNORE_ID else obj // ID_CLASS_DIVISOR
            if cls not in VALID_CLASSES:
                raise DataFormatError(path, f"object id {obj} has class {cls}, not 1, 2 or 10")
            rows.append((int(path.stem), obj, cls, h, w, 1.0))
            counts.append(rle)
    return _build(rows, counts, [0] * len(rows), folder)


def write_instances_png(folder: str | os.PathLike, ann: MaskAnnotations, frames: Sequence[int],
                        image_size: tuple[int, int]) -> None:
    """Write non-overlapping records as MOTS pngs ``<folder>/<frame:06d>.png`` for ``frames``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    height, width = image_size
    for t in frames:
        idx = ann.rows(t)
        image = np.zeros((height, width), dtype=np.uint16)
        for i, mask in zip(idx, ann.decode(idx, height, width), strict=True):
            image[mask] = ann.ids[i]
        path = folder / f"{int(t):06d}.png"
        if not cv2.imwrite(str(path), image):
            raise OSError(f"{path}: cv2.imwrite failed")

