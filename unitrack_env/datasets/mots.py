"""Readers and writers of the MOTS formats: MOTS Challenge (MOTS20) and KITTI MOTS.

Format (Voigtlaender et al., "MOTS: Multi-Object Tracking and Segmentation", CVPR 2019;
https://www.vision.rwth-aachen.de/page/mots, restated in TrackEval's ``docs/MOTS-format.txt``):

* **txt** (``instances_txt``): one line per object and frame,
  ``time_frame id class_id img_height img_width rle``, space-separated, where ``rle`` is a
  COCO compressed run-length encoding (``pycocotools.mask``) of the ``img_height x
  img_width`` mask. Object ids are ``class_id * 1000 + instance``; class ids are 1 (car) and
  2 (pedestrian); id 10000 with class 10 is an ignore region. Masks of one frame never
  overlap (TrackEval rejects overlapping ground truth and results).
* **png** (``instances/<seq>/<frame>.png``): one 16-bit single-channel image per frame whose
  pixel values are the object ids (0 = background, 10000 = ignore).

On-disk layouts read here:

* MOTS Challenge (MOTS20, the MOTChallenge layout): ``<root>/<split>/<seq>/seqinfo.ini``,
  ``img1/000001.jpg`` ..., ground truth ``gt/gt.txt`` (txt format, 1-based ``time_frame``;
  TrackEval's ``MOTSChallenge`` reads ``{gt_folder}/{seq}/gt/gt.txt``).
* KITTI MOTS: frames ``<root>/<split>/image_02/<seq>/000000.png`` (KITTI tracking's
  ``training`` / ``testing`` folders), ground truth ``<root>/instances_txt/<seq>.txt`` or
  ``<root>/instances/<seq>/000000.png`` (0-based ``time_frame``, as TrackEval's ``KittiMOTS``
  reads it); 10 frames per second.

Detections. Neither benchmark ships public mask detections; detection files use the txt line
format with an optional 7th field, the detection score (1.0 when absent); the ``id`` field
is ignored. ``"public"`` means ``<seq>/det/det.txt`` (MOTS20 layout) or
``<root>/<split>/det_02/<seq>.txt`` (KITTI layout), the places where the embedded synthetic
data sets put theirs; any folder of ``<seq>.txt`` files can be given instead, and ``"gt"``
turns the ground-truth masks of the tracked class into detections (an oracle, with score 1).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import cv2
import numpy as np

from unitrack_env.datasets.motchallenge import read_seqinfo
from unitrack_env.errors import DataFormatError

#: Benchmarks (layouts) read by :class:`MOTSDataset`.
BENCHMARKS = ("MOTS20", "KITTI-MOTS")
#: Class ids of the format.
CLASS_CAR = 1
CLASS_PEDESTRIAN = 2
CLASS_IGNORE = 10
#: Object id of ignore regions in the png format.
IGNORE_ID = 10000
#: ``class_id = obj_id // ID_CLASS_DIVISOR`` in the png format.
ID_CLASS_DIVISOR = 1000
#: Class names (TrackEval's) and ids.
CLASS_IDS = MappingProxyType({"car": CLASS_CAR, "pedestrian": CLASS_PEDESTRIAN})
#: Valid class ids in txt files.
VALID_CLASSES = frozenset({CLASS_CAR, CLASS_PEDESTRIAN, CLASS_IGNORE})
#: Fields of a txt line (a 7th, ``score``, is allowed in detection files).
TXT_FIELDS = ("time_frame", "id", "class_id", "img_height", "img_width", "rle")
#: KITTI MOTS frame rate (KITTI's cameras run at 10 Hz).
KITTI_FRAME_RATE = 10.0
#: Splits of the KITTI tracking image folders.
KITTI_SPLITS = ("training", "testing")


# ------------------------------------------------------------------------------- RLE
def encode_masks(masks: np.ndarray) -> list[bytes]:
    """Return the COCO compressed RLE strings of an ``(n, H, W)`` stack of binary masks."""
    from pycocotools import mask as mask_utils

    masks = np.asarray(masks)
    if masks.ndim != 3:
        raise ValueError(f"masks must be (n, H, W), got shape {masks.shape}")
    if not len(masks):
        return []
    fortran = np.asfortranarray(masks.transpose(1, 2, 0).astype(np.uint8))
    return [rle["counts"] for rle in mask_utils.encode(fortran)]


def decode_masks(counts: Sequence[bytes], height: int, width: int) -> np.ndarray:
    """Decode COCO compressed RLE strings of ``height x width`` masks to ``(n, H, W)`` bool."""
    from pycocotools import mask as mask_utils

    if not len(counts):
        return np.zeros((0, height, width), dtype=bool)
    rles = [{"size": [int(height), int(width)], "counts": c} for c in counts]
    decoded = mask_utils.decode(rles)  # (H, W, n) uint8, Fortran order
    return np.ascontiguousarray(decoded.transpose(2, 0, 1)).astype(bool)


def rle_runs(counts: bytes) -> np.ndarray:
    """Decode a COCO compressed RLE string to its run lengths (no mask is built).

    The string holds one number per run, 5 bits per character (offset 48, bit 5 = "more
    characters follow", bit 4 of the last character = sign); from the fourth run on, each
    number is the difference to the run two places before.

    Raises:
        ValueError: a character outside the alphabet, or a number cut short.
    """
    codes = np.frombuffer(counts, dtype=np.uint8).astype(np.int64) - 48
    if not len(codes):
        return np.zeros(0, dtype=np.int64)
    if codes.min() < 0 or codes.max() > 63:
        bad = int(np.argmax((codes < 0) | (codes > 63)))
        raise ValueError(f"character {chr(counts[bad])!r} at position {bad} is not RLE text")
    ends = (codes & 0x20) == 0
    if not ends[-1]:
        raise ValueError("the last number is cut short")
    stops = np.flatnonzero(ends)
    starts = np.concatenate([[0], stops[:-1] + 1])
    group = np.repeat(np.arange(len(starts)), stops - starts + 1)
    position = np.arange(len(codes)) - starts[group]
    values = np.bincount(group, weights=(codes & 0x1F) << (5 * position)).astype(np.int64)
    sizes = stops - starts + 1
    negative = (codes[stops] & 0x10) != 0
    values[negative] -= np.left_shift(1, 5 * sizes[negative])
    runs = values.copy()
    runs[1::2] = np.cumsum(values[1::2])
    runs[2::2] = np.cumsum(values[2::2])
    return runs


def check_rle(counts: bytes, height: int, width: int) -> str | None:
    """Return why a compressed RLE is not a ``height x width`` mask, or None when it is."""
    try:
        runs = rle_runs(counts)
    except ValueError as exc:
        return f"corrupt RLE ({exc})"
    if len(runs) and runs.min() < 0:
        return "corrupt RLE (a negative run length)"
    total = int(runs.sum())
    if total != height * width:
        return (f"RLE run lengths sum to {total} pixels, but a {height}x{width} mask has "
                f"{height * width}")
    return None


def resolve_overlaps(masks: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """Give each pixel claimed by several masks to the highest-scored one (MOTS: disjoint).

    Ties keep the earlier mask. Returns a new ``(n, H, W)`` bool stack.
    """
    masks = np.asarray(masks, dtype=bool)
    out = np.zeros_like(masks)
    taken = np.zeros(masks.shape[1:], dtype=bool)
    for i in np.argsort(-np.asarray(scores, dtype=np.float64), kind="stable"):
        out[i] = masks[i] & ~taken
        taken |= out[i]
    return out


# ------------------------------------------------------------------------- records
@dataclass(frozen=True)
class MaskAnnotations:
    """Mask rows of a MOTS txt/png file (ground truth, detections or results).

    Attributes:
        frames: ``(n,)`` ``time_frame`` as in the file (MOTS20 1-based, KITTI 0-based).
        ids: ``(n,)`` object ids.
        classes: ``(n,)`` class ids.
        heights: ``(n,)`` image heights of the masks.
        widths: ``(n,)`` image widths.
        counts: ``n`` COCO compressed RLE strings.
        scores: ``(n,)`` detection scores (1.0 where the file has none).
        lines: ``(n,)`` 1-based line numbers in the source file (0 for png input).
        source: the file or folder read (None when built in memory).
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
        """Decode rows ``idx`` (masks of a ``height x width`` frame) to ``(k, H, W)`` bool.

        Raises:
            DataFormatError: a row's size differs from the frame's, or its RLE is corrupt
                (naming the file and line).
        """
        idx = np.asarray(idx, dtype=np.int64)
        for i in idx:
            if (self.heights[i], self.widths[i]) != (height, width):
                raise self._error(int(i), f"mask is {self.widths[i]}x{self.heights[i]} but the "
                                  f"frame is {width}x{height}", "img_height")
        try:
            return decode_masks([self.counts[i] for i in idx], height, width)
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
    path: str | os.PathLike, *, allow_score: bool = False, text: str | None = None
) -> MaskAnnotations:
    """Read a MOTS txt file (``time_frame id class_id img_height img_width rle``).

    Args:
        path: the file (also named in errors when ``text`` is given).
        allow_score: accept a 7th field, the detection score (detection files).
        text: the file's contents, if already read.

    Raises:
        DataFormatError: naming the file, the 1-based line and the field of the first
            problem (field count, non-integer, unknown class, non-positive size).
    """
    path = Path(path)
    if text is None:
        try:
            text = path.read_text(encoding="ascii")
        except FileNotFoundError:
            raise DataFormatError(path, "file not found") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise DataFormatError(path, f"cannot read MOTS txt file ({exc})") from None
    rows: list[tuple] = []
    counts: list[bytes] = []
    lines: list[int] = []
    allowed = (6, 7) if allow_score else (6,)
    for lineno, line in enumerate(text.splitlines(), start=1):
        parts = line.split()
        if not parts:
            continue
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
        if cls not in VALID_CLASSES:
            raise DataFormatError(path, f"class {cls} is not 1 (car), 2 (pedestrian) or 10 "
                                  "(ignore)", line=lineno, field="class_id")
        if h < 1 or w < 1:
            raise DataFormatError(path, f"image size {h}x{w} must be positive", line=lineno,
                                  field="img_height")
        if t < 0:
            raise DataFormatError(path, f"time_frame {t} is negative", line=lineno,
                                  field="time_frame")
        score = 1.0
        if len(parts) == 7:
            try:
                score = float(parts[6])
            except ValueError:
                raise DataFormatError(path, f"{parts[6]!r} is not a number", line=lineno,
                                      field="score") from None
            if not np.isfinite(score):
                raise DataFormatError(path, "score is not finite", line=lineno, field="score")
        rle = parts[5].encode("ascii", errors="replace")
        problem = check_rle(rle, h, w)
        if problem is not None:
            raise DataFormatError(path, problem, line=lineno, field="rle")
        rows.append((t, obj, cls, h, w, score))
        counts.append(rle)
        lines.append(lineno)
    return _build(rows, counts, lines, path)


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
    """Read a folder of MOTS png annotations (``<frame>.png``, 16-bit object ids).

    Frames are the file names' numbers; objects ``0 < id`` become rows with
    ``class = id // 1000`` (the ignore id 10000 becomes class 10).

    Raises:
        DataFormatError: the folder is missing or empty, a file is not a 16-bit
            single-channel png, or a file name is not a frame number.
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
    """Write records as MOTS png files ``<folder>/<frame:06d>.png`` for every frame listed.

    Args:
        folder: output folder (created).
        ann: records whose masks do not overlap.
        frames: frame numbers to write (frames without rows give an all-zero png).
        image_size: ``(height, width)``.
    """
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


# ------------------------------------------------------------------------- data set
@dataclass(frozen=True)
class MOTSSequenceInfo:
    """Where a sequence's frames are and how they are numbered.

    Attributes:
        name: sequence name.
        image_dir: folder of the frames.
        length: number of frames.
        first_frame: number of the first frame in file names and ``time_frame`` (MOTS20 1,
            KITTI 0).
        width: frame width.
        height: frame height.
        frame_rate: frames per second.
        image_ext: frame file extension.
    """

    name: str
    image_dir: Path
    length: int
    first_frame: int
    width: int
    height: int
    frame_rate: float
    image_ext: str

    def frame_path(self, frame: int) -> Path:
        """Image file of a frame number (file numbering)."""
        return self.image_dir / f"{frame:06d}{self.image_ext}"


class MOTSDataset:
    """A MOTS data set on disk in the MOTS20 or the KITTI MOTS layout (module docstring).

    Args:
        root: the benchmark folder (MOTS20: holding ``train/``, ``test/``; KITTI MOTS:
            holding ``training/image_02``, ``instances_txt`` or ``instances``).
        benchmark: ``"MOTS20"`` or ``"KITTI-MOTS"``.
        split: MOTS20 ``"train"`` / ``"test"``; KITTI ``"training"`` / ``"testing"``.
        detections: ``"public"``, ``"gt"`` or a folder of ``<seq>.txt`` detection files.

    Raises:
        DataFormatError: missing folders or no sequences.
    """

    def __init__(self, root: str | os.PathLike, benchmark: str = "MOTS20", split: str = "train",
                 detections: str | os.PathLike = "public") -> None:
        if benchmark not in BENCHMARKS:
            raise ValueError(
                f"unknown MOTS benchmark {benchmark!r}; valid: {', '.join(BENCHMARKS)}")
        self.root = Path(root)
        self.benchmark = benchmark
        self.split = split
        self.detections = detections
        if benchmark == "MOTS20":
            self.split_dir = self.root / split
        else:
            if split not in KITTI_SPLITS:
                raise ValueError(f"KITTI MOTS split must be one of {KITTI_SPLITS}, got {split!r}")
            self.split_dir = self.root / split / "image_02"
        if not self.split_dir.is_dir():
            raise DataFormatError(self.split_dir, f"{benchmark} split folder not found")
        self.sequence_names = sorted(p.name for p in self.split_dir.iterdir() if p.is_dir())
        if not self.sequence_names:
            raise DataFormatError(self.split_dir, "contains no sequence folders")

    # -------------------------------------------------------------- paths
    def gt_path(self, name: str) -> Path:
        """The ground-truth file (txt) or folder (png) of a sequence (it may not exist)."""
        if self.benchmark == "MOTS20":
            return self.split_dir / name / "gt" / "gt.txt"
        txt = self.root / "instances_txt" / f"{name}.txt"
        png = self.root / "instances" / name
        return txt if txt.is_file() or not png.is_dir() else png

    def detection_path(self, name: str) -> Path:
        """The detection file of a sequence (for ``detections != "gt"``)."""
        if str(self.detections) == "public":
            if self.benchmark == "MOTS20":
                return self.split_dir / name / "det" / "det.txt"
            return self.root / self.split / "det_02" / f"{name}.txt"
        return Path(self.detections) / f"{name}.txt"

    def has_ground_truth(self, name: str) -> bool:
        """Whether the sequence has ground truth (txt file or png folder)."""
        path = self.gt_path(name)
        return path.is_file() or path.is_dir()

    # -------------------------------------------------------------- reading
    def info(self, name: str) -> MOTSSequenceInfo:
        """The sequence's frame layout (cheap: seqinfo.ini or one directory listing)."""
        if name not in self.sequence_names:
            raise KeyError(f"no sequence {name!r} in {self.split_dir}")
        if self.benchmark == "MOTS20":
            seq = read_seqinfo(self.split_dir / name)
            return MOTSSequenceInfo(name, seq.path / seq.image_dir, seq.length, 1, seq.width,
                                    seq.height, seq.frame_rate, seq.image_ext)
        folder = self.split_dir / name
        files = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".png", ".jpg"))
        if not files:
            raise DataFormatError(folder, "contains no frames (000000.png ...)")
        first = cv2.imread(str(files[0]), cv2.IMREAD_UNCHANGED)
        if first is None:
            raise DataFormatError(files[0], "not a decodable image")
        return MOTSSequenceInfo(name, folder, len(files), int(files[0].stem), first.shape[1],
                                first.shape[0], KITTI_FRAME_RATE, files[0].suffix)

    def ground_truth(self, name: str) -> MaskAnnotations | None:
        """The sequence's ground truth, or None on a split without it."""
        if not self.has_ground_truth(name):
            return None
        path = self.gt_path(name)
        gt = read_instances_png(path) if path.is_dir() else parse_instances_txt(path)
        check_ground_truth(gt, self.info(name))
        return gt

    def load_detections(self, name: str, class_id: int) -> MaskAnnotations:
        """The sequence's detections of class ``class_id``.

        Raises:
            DataFormatError: the detection file is missing (naming where it was expected).
        """
        if str(self.detections) == "gt":
            gt = self.ground_truth(name)
            if gt is None:
                raise DataFormatError(self.gt_path(name), "detections='gt' needs ground truth, "
                                      "which this split does not have")
            keep = gt.classes == class_id
            return gt.select(keep)
        path = self.detection_path(name)
        if not path.is_file():
            raise DataFormatError(path, "detection file not found; MOTS benchmarks ship no "
                                  "public mask detections: pass detections=<folder of <seq>.txt> "
                                  "or detections='gt'")
        dets = parse_instances_txt(path, allow_score=True)
        return dets.select(dets.classes == class_id)


def check_ground_truth(gt: MaskAnnotations, info: MOTSSequenceInfo) -> None:
    """Refuse ground truth that TrackEval would refuse when scoring, naming file and line.

    Checks: every ``time_frame`` is a frame of the sequence, every mask has the frame's
    size, no object id twice in one frame, and no two masks of a frame overlap (TrackEval's
    MOTS readers reject overlapping masks). Works on the run-length encodings (no mask is
    decoded).

    Raises:
        DataFormatError: the first problem found.
    """
    from pycocotools import mask as mask_utils

    last = info.first_frame + info.length - 1
    for i in range(len(gt)):
        if not info.first_frame <= gt.frames[i] <= last:
            raise gt._error(i, f"time_frame {gt.frames[i]} is not a frame of the sequence "
                               f"({info.first_frame}..{last})", "time_frame")
        if (gt.heights[i], gt.widths[i]) != (info.height, info.width):
            raise gt._error(i, f"mask is {gt.widths[i]}x{gt.heights[i]} but the frames are "
                               f"{info.width}x{info.height}", "img_height")
    for frame in np.unique(gt.frames):
        idx = gt.rows(frame)
        ids = gt.ids[idx]
        if len(np.unique(ids)) != len(ids):
            seen: set[int] = set()
            for i in idx:
                if int(gt.ids[i]) in seen:
                    raise gt._error(int(i), f"id {gt.ids[i]} appears twice in frame {frame}",
                                    "id")
                seen.add(int(gt.ids[i]))
        rles = gt.rles(idx)
        if len(rles) < 2:
            continue
        union = mask_utils.area(mask_utils.merge(rles, intersect=False))
        if int(union) != int(mask_utils.area(rles).sum()):
            merged = rles[0]
            for k in range(1, len(rles)):
                if mask_utils.area(mask_utils.merge([merged, rles[k]], intersect=True)) > 0:
                    raise gt._error(
                        int(idx[k]), f"mask of id {gt.ids[idx[k]]} overlaps another mask of frame "
                                     f"{frame}; MOTS masks of one frame must be disjoint "
                                     "(TrackEval refuses overlapping masks)", "rle")
                merged = mask_utils.merge([merged, rles[k]], intersect=False)
