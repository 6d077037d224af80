"""Reader for KITTI tracking: ``image_02/<seq>/%06d.png``, ``label_02/<seq>.txt``, seqmaps.

``<root>/<split>/`` holds ``image_02/<seq>/000000.png...`` (frames numbered from 0),
``label_02/<seq>.txt`` (17 space-separated columns: ``frame track_id type truncated
occluded alpha x1 y1 x2 y2 h w l X Y Z rotation_y``) and optionally
``evaluate_tracking.seqmap.<split>`` (``<seq> empty <first> <last+1>`` per line, as the
devkit's); without one, a sequence's length is its number of images. Detections are the
user's, in the result format (the 17 columns and a score): ``<folder>/<seq>.txt``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from unitrack_env.datasets.limits import MAX_FRAMES
from unitrack_env.errors import DataFormatError, UnknownSequenceError

#: The classes KITTI tracking evaluates, and their ids in observations and results.
EVALUATED = ("Car", "Pedestrian")
CLASS_IDS = {"Car": 1, "Pedestrian": 2}
#: Columns of a label row, for messages.
FIELDS = ("frame", "track_id", "type", "truncated", "occluded", "alpha", "x1", "y1", "x2",
          "y2", "h", "w", "l", "X", "Y", "Z", "rotation_y", "score")
#: The 8 KITTI object types and DontCare (TrackEval lower-cases them).
TYPES = frozenset({"Car", "Van", "Truck", "Pedestrian", "Person_sitting", "Cyclist", "Tram",
                   "Misc", "DontCare"})
#: Where detections are looked for when ``detections=`` is not given.
DEFAULT_DETECTIONS = "det_02"


@dataclass(frozen=True)
class KITTIRows:
    """Rows of a label or result file: frame (0-based), id, type, box ``x1 y1 x2 y2``, score."""

    frames: np.ndarray
    ids: np.ndarray
    types: np.ndarray
    boxes: np.ndarray
    scores: np.ndarray

    def at(self, frame: int) -> np.ndarray:
        """Indices of the rows of ``frame``."""
        return np.flatnonzero(self.frames == frame)


def read_kitti_rows(path: Path, length: int, *, min_columns: int = 17) -> KITTIRows:
    """Parse a KITTI tracking file; DataFormatError names the line and field of a problem."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DataFormatError(path, "missing") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFormatError(path, f"unreadable ({exc})") from None
    frames, ids, types, boxes, scores = [], [], [], [], []
    for lineno, line in enumerate(text.splitlines(), start=1):
        cells = line.split()
        if not cells:
            continue
        if len(cells) < min_columns:
            raise DataFormatError(path, f"{len(cells)} columns, expected at least {min_columns} "
                                        "(KITTI tracking's space-separated format)", line=lineno)
        numbers = []
        for col in (0, 1, 6, 7, 8, 9, *((17,) if len(cells) > 17 else ())):
            try:
                value = float(cells[col])
            except ValueError:
                raise DataFormatError(path, f"'{cells[col]}' is not a number", line=lineno,
                                      field=FIELDS[col]) from None
            if not math.isfinite(value):
                raise DataFormatError(path, f"'{cells[col]}' is not finite", line=lineno,
                                      field=FIELDS[col])
            numbers.append(value)
        if not numbers[0].is_integer() or not 0 <= numbers[0] < length:
            raise DataFormatError(path, f"frame {cells[0]} is not one of the sequence's "
                                        f"{length} frames (0..{length - 1})", line=lineno,
                                  field="frame")
        if not numbers[1].is_integer():
            raise DataFormatError(path, f"'{cells[1]}' is not an integer", line=lineno,
                                  field="track_id")
        if cells[2] not in TYPES:
            raise DataFormatError(path, f"unknown type '{cells[2]}'; KITTI's are "
                                        f"{', '.join(sorted(TYPES))}", line=lineno, field="type")
        if numbers[4] < numbers[2] or numbers[5] < numbers[3]:
            raise DataFormatError(path, "x2 < x1 or y2 < y1", line=lineno, field="x1")
        frames.append(int(numbers[0]))
        ids.append(int(numbers[1]))
        types.append(cells[2])
        boxes.append(numbers[2:6])
        scores.append(numbers[6] if len(numbers) > 6 else 1.0)
    return KITTIRows(np.asarray(frames, dtype=np.int64), np.asarray(ids, dtype=np.int64),
                     np.asarray(types, dtype=object), np.asarray(boxes, float).reshape(-1, 4),
                     np.asarray(scores, dtype=np.float64))


@dataclass(frozen=True)
class KITTISequence:
    """One sequence: name, frame folder, length, image size, detections and ground truth."""

    name: str
    image_dir: Path
    length: int
    size: tuple[int, int]
    detections: KITTIRows
    ground_truth: KITTIRows | None

    def frame_path(self, frame: int) -> Path:
        """The image of 0-based ``frame``."""
        return self.image_dir / f"{frame:06d}.png"


class KITTITrackingDataset:
    """The sequences of one split (``training`` or ``testing``) of KITTI tracking."""

    def __init__(self, root: str | Path, split: str = "training",
                 detections: str | Path | None = None) -> None:
        self.root, self.split = Path(root), split
        self.split_dir = self.root / split
        images = self.split_dir / "image_02"
        if not images.is_dir():
            raise DataFormatError(images, "missing; root= should be KITTI's tracking folder "
                                          f"holding {split}/image_02/<seq>/ and "
                                          f"{split}/label_02/<seq>.txt")
        self.lengths = self._lengths(images)
        self.sequence_names = sorted(self.lengths)
        if not self.sequence_names:
            raise DataFormatError(images, "holds no sequence folders of .png frames")
        self.detections = (Path(detections) if detections is not None
                           else self.split_dir / DEFAULT_DETECTIONS)

    def _lengths(self, images: Path) -> dict[str, int]:
        seqmap = self.split_dir / f"evaluate_tracking.seqmap.{self.split}"
        if seqmap.is_file():
            lengths = {}
            for lineno, line in enumerate(seqmap.read_text().splitlines(), start=1):
                cells = line.split()
                if not cells:
                    continue
                if len(cells) < 4 or not cells[3].isdigit():
                    raise DataFormatError(seqmap, "expected '<seq> empty <first> <end>'",
                                          line=lineno)
                lengths[cells[0]] = int(cells[3])
        else:
            lengths = {p.name: len(list(p.glob("*.png"))) for p in images.iterdir()
                       if p.is_dir()}
        too_long = [n for n, k in lengths.items() if k > MAX_FRAMES]
        if too_long:
            raise DataFormatError(seqmap, f"{too_long[0]}: more than {MAX_FRAMES:,} frames")
        return {name: k for name, k in lengths.items() if k > 0}

    def label_path(self, name: str) -> Path:
        """``<split>/label_02/<name>.txt``."""
        return self.split_dir / "label_02" / f"{name}.txt"

    def detection_path(self, name: str) -> Path:
        """``<detections>/<name>.txt``."""
        return self.detections / f"{name}.txt"

    def has_ground_truth(self, name: str) -> bool:
        """Whether ``name`` has a label file."""
        return self.label_path(name).is_file()

    def load(self, name: str, *, check_frames: bool = True) -> KITTISequence:
        """Read one sequence (``check_frames``: every frame image must exist)."""
        if name not in self.lengths:
            raise UnknownSequenceError(f"no sequence '{name}' in {self.split_dir}; available: "
                                       f"{', '.join(self.sequence_names)}")
        length = self.lengths[name]
        image_dir = self.split_dir / "image_02" / name
        if check_frames:
            for frame in range(length):
                if not (image_dir / f"{frame:06d}.png").is_file():
                    raise DataFormatError(image_dir / f"{frame:06d}.png",
                                          f"missing frame {frame} of {length}")
        size = _png_size(image_dir / "000000.png")
        gt = (read_kitti_rows(self.label_path(name), length)
              if self.has_ground_truth(name) else None)
        detections = read_kitti_rows(self.detection_path(name), length, min_columns=10)
        return KITTISequence(name, image_dir, length, size, detections, gt)


def _png_size(path: Path) -> tuple[int, int]:
    """``(width, height)`` from a PNG header."""
    try:
        head = path.read_bytes()[:24]
    except OSError:
        raise DataFormatError(path, "missing (the first frame)") from None
    if head[:8] != b"\x89PNG\r\n\x1a\n":
        raise DataFormatError(path, "not a PNG image (KITTI frames are .png)")
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
