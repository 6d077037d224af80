"""Reader for the MOTChallenge layout (MOT15/16/17/20, DanceTrack, SportsMOT, custom data).

Reads ``<root>/<split>/<sequence>/`` with ``seqinfo.ini``, ``img1/``, ``det/det.txt`` and
``gt/gt.txt`` (train splits); where each benchmark keeps them is its
:class:`~unitrack_env.datasets.mot_layouts.MOTLayout`. Columns are read by position, with the
quirks seen in real releases: ``det.txt`` of 10 columns (``frame,-1,x,y,w,h,score,-1,-1,-1``)
or 7, rows in any order, unbounded scores (MOT15's run past 100); ``gt.txt`` of 9 columns
(``frame,id,x,y,w,h,flag,class,visibility``, MOT16/17/20) or MOT15's 10 without a class
(``frame,id,x,y,w,h,flag,wx,wy,wz``), sorted by id or by frame.
"""

from __future__ import annotations

import configparser
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from unitrack_env.datasets.limits import MAX_FRAMES, check_image_size
from unitrack_env.datasets.mot_classes import ClassMap
from unitrack_env.datasets.mot_layouts import LAYOUTS, MOTLayout, read_seqmap
from unitrack_env.datasets.mot_signatures import check_signature
from unitrack_env.datasets.motchallenge_tables import DET_FIELDS, GT_FIELDS, check_rows, parse_table
from unitrack_env.errors import DataFormatError, UnknownSequenceError

#: Benchmarks whose ground truth has the 9-column class/visibility layout.
CLASS_COLUMN_BENCHMARKS = frozenset(name for name, layout in LAYOUTS.items()
                                    if layout.class_column)
#: All benchmark rule sets understood by the reader and the official scorer.
BENCHMARKS = frozenset(LAYOUTS)
#: Where a benchmark without public detections finds the user's, below its root (``{split}``
#: filled in): unitrack's convention, not the benchmark's; the embedded default ships there.
DETECTIONS_FOLDER = "detections/{split}"
#: Class id of pedestrians in MOT16/17/20 ground truth (the evaluated class).
PEDESTRIAN_CLASS = 1
#: Keys every ``seqinfo.ini`` needs.
_SEQINFO_FIELDS = ("name", "imDir", "frameRate", "seqLength", "imWidth", "imHeight", "imExt")

__all__ = [
    "BENCHMARKS",
    "CLASS_COLUMN_BENCHMARKS",
    "PEDESTRIAN_CLASS",
    "Annotations",
    "MOTChallengeDataset",
    "MOTSequence",
    "SequenceInfo",
    "read_detections",
    "read_ground_truth",
    "read_seqinfo",
]


@dataclass(frozen=True)
class SequenceInfo:
    """What ``seqinfo.ini`` says about a sequence, plus where its files are."""

    name: str
    path: Path
    frame_rate: float
    length: int
    width: int
    height: int
    image_dir: str = "img1"
    image_ext: str = ".jpg"
    frame_digits: int = 6

    def frame_path(self, frame: int) -> Path:
        """Return the image file of a 1-based frame index (``000001.jpg``; DanceTrack: 8 digits)."""
        return self.path / self.image_dir / f"{frame:0{self.frame_digits}d}{self.image_ext}"


@dataclass(frozen=True)
class Annotations:
    """Rows of a detection or ground-truth file, sorted by frame, with per-frame access.

    Boxes as written (1-based pixels); ``ids`` -1 for detections; ``scores`` is the gt's flag
    column (0 = ignore); ``classes`` and ``visibility`` default to 1 where the file has none.
    """

    frames: np.ndarray
    ids: np.ndarray
    boxes: np.ndarray
    scores: np.ndarray
    classes: np.ndarray
    visibility: np.ndarray
    _offsets: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if self._offsets is None:
            last = int(self.frames.max()) if len(self.frames) else 0
            offsets = np.searchsorted(self.frames, np.arange(last + 2))
            object.__setattr__(self, "_offsets", offsets)

    def __len__(self) -> int:
        return len(self.frames)

    def rows(self, frame: int) -> slice:
        """Return the slice of rows that belong to ``frame``."""
        if frame < 0 or frame + 1 >= len(self._offsets):
            return slice(0, 0)
        return slice(int(self._offsets[frame]), int(self._offsets[frame + 1]))

    def count_per_frame(self, length: int) -> np.ndarray:
        """Return the number of rows of each frame ``1..length`` (index 0 is frame 1)."""
        counts = np.bincount(self.frames, minlength=length + 1)
        return counts[1 : length + 1]

    def filter(self, keep: np.ndarray) -> Annotations:
        """Return the rows where ``keep`` is true."""
        return Annotations(
            self.frames[keep],
            self.ids[keep],
            self.boxes[keep],
            self.scores[keep],
            self.classes[keep],
            self.visibility[keep],
        )


def _read_ini(path: Path) -> configparser.ConfigParser:
    """Parse an INI file; a UTF-8 byte-order mark is skipped, with a warning."""
    parser = configparser.ConfigParser(interpolation=None)
    parser.optionxform = str  # keep the keys' case (imDir, frameRate, ...)
    try:
        raw = path.read_bytes()
        # A byte-order mark (Windows editors write one) is skipped, not read as part of the
        # "[Sequence]" header. Our scoring passes the length to TrackEval (SEQ_INFO); only
        # TrackEval run by itself on the folder reads this file, and fails on a BOM.
        if raw.startswith(b"\xef\xbb\xbf"):
            warnings.warn(f"{path}: starts with a UTF-8 byte-order mark (BOM); read without "
                          "it, but TrackEval run by itself on this folder would fail on it: "
                          "save the file without a BOM", stacklevel=3)
        parser.read_string(raw.decode("utf-8-sig", errors="strict"))
    except (configparser.Error, UnicodeDecodeError) as exc:
        raise DataFormatError(path, f"not a valid INI file ({exc})") from None
    return parser


def read_seqinfo(seq_dir: str | Path, frame_digits: int = 6) -> SequenceInfo:
    """Read ``<seq_dir>/seqinfo.ini``; DataFormatError names a missing file, section or field.

    ``frame_digits``: of the frame files' names, which seqinfo.ini does not state.
    """
    seq_dir = Path(seq_dir)
    path = seq_dir / "seqinfo.ini"
    if not path.is_file():
        raise DataFormatError(path, "missing; every MOTChallenge sequence needs a seqinfo.ini")
    parser = _read_ini(path)
    if not parser.has_section("Sequence"):
        raise DataFormatError(path, "has no [Sequence] section")
    section = parser["Sequence"]
    values: dict[str, str] = {}
    for key in _SEQINFO_FIELDS:
        if key not in section or not section[key].strip():
            raise DataFormatError(path, "missing", field=key)
        values[key] = section[key].strip()

    def number(key: str, kind: type) -> float | int:
        text = values[key]
        try:
            value = float(text)
        except ValueError:
            raise DataFormatError(path, f"'{text}' is not a number", field=key) from None
        if not math.isfinite(value) or value <= 0:
            raise DataFormatError(path, f"must be a finite positive number, got {text}",
                                  field=key)
        if kind is int:
            if not value.is_integer():
                raise DataFormatError(path, f"must be a whole number, got {text}", field=key)
            return int(value)
        return value

    length, width, height = (int(number(key, int)) for key in ("seqLength", "imWidth",
                                                                 "imHeight"))
    if length > MAX_FRAMES:
        raise DataFormatError(path, f"{length} frames, more than {MAX_FRAMES:,} (9 hours at 30 "
                                    "fps; the longest benchmark sequences have a few "
                                    "thousand)", field="seqLength")
    check_image_size(path, (width, height), field="imWidth/imHeight")
    ext = values["imExt"]
    return SequenceInfo(
        name=values["name"],
        path=seq_dir,
        frame_rate=float(number("frameRate", float)),
        length=length,
        width=width,
        height=height,
        image_dir=values["imDir"],
        image_ext=ext if ext.startswith(".") else f".{ext}",
        frame_digits=frame_digits,
    )


def _annotations(table: np.ndarray, ids: np.ndarray, scores: np.ndarray,
                 classes: np.ndarray, visibility: np.ndarray) -> Annotations:
    order = np.argsort(table[:, 0], kind="stable")
    return Annotations(
        frames=table[order, 0].astype(np.int64),
        ids=ids[order].astype(np.int64),
        boxes=np.ascontiguousarray(table[order, 2:6]),
        scores=scores[order].astype(np.float64),
        classes=classes[order].astype(np.int64),
        visibility=visibility[order].astype(np.float64),
    )


def read_detections(path: str | Path, length: int | None = None,
                    class_map: ClassMap | None = None) -> Annotations:
    """Read a ``det.txt``-format file; rows past ``length`` frames are errors.

    With a ``class_map``, column 8 holds each detection's class id (one the map names).
    """
    path = Path(path)
    table, lines = parse_table(path, 7, DET_FIELDS)
    if class_map is not None and len(table) and table.shape[1] < 8:
        raise DataFormatError(path, f"{table.shape[1]} columns: with a class map each "
                              "detection carries its class id in column 8", line=int(lines[0]),
                              field="class")
    check_rows(path, table, lines, length, "det")
    n = len(table)
    if not n:
        warnings.warn(f"{path}: contains no detections; every frame of the sequence will be "
                      "observed without any (and score zero)", stacklevel=2)
    classes = np.ones(n)
    if class_map is not None:
        classes = table[:, 7]
        class_map.check_column(path, classes, lines, what="detection")
    return _annotations(table, np.full(n, -1), table[:, 6], classes, np.ones(n))


def read_ground_truth(path: str | Path, benchmark: str, length: int | None = None,
                      class_map: ClassMap | None = None) -> Annotations:
    """Read a ``gt.txt`` file with the column rules of ``benchmark``.

    MOT16/17/20 files have ``flag, class, visibility`` in columns 7-9; MOT15 files have only
    the flag (column 7), every row being a pedestrian. With a ``class_map`` the class column
    is required and every id in it must be one the map names (not necessarily 1..13).
    """
    path = Path(path)
    if benchmark not in BENCHMARKS:
        raise ValueError(f"unknown benchmark '{benchmark}'; valid: {sorted(BENCHMARKS)}")
    has_class = benchmark in CLASS_COLUMN_BENCHMARKS or class_map is not None
    table, lines = parse_table(path, 9 if has_class else 7, GT_FIELDS, official=True)
    check_rows(path, table, lines, length, "gt", has_class=has_class and class_map is None)
    if class_map is not None:
        class_map.check_column(path, table[:, 7], lines)
    n = len(table)
    classes = table[:, 7] if has_class else np.full(n, PEDESTRIAN_CLASS)
    visibility = table[:, 8] if has_class else np.ones(n)
    return _annotations(table, table[:, 1], table[:, 6], classes, visibility)


@dataclass(frozen=True)
class MOTSequence:
    """One sequence: its info, detections, and ground truth when the split has it."""

    info: SequenceInfo
    detections: Annotations
    ground_truth: Annotations | None

    @property
    def name(self) -> str:
        """The sequence's folder name."""
        return self.info.path.name


def _root_hint(root: Path, split: Path, benchmark: str) -> str:
    """Where ``root`` probably should point when it has no ``split`` folder (relative path)."""
    if not root.is_dir():
        return ""
    present = sorted(p for p in root.iterdir() if p.is_dir())
    inside = [p for p in present if (p / split).is_dir()]
    if inside:  # one level too high: root=data instead of data/MOT17
        best = next((p for p in inside if p.name == benchmark), inside[0])
        return f"; did you mean root={best}?"
    if any((p / "seqinfo.ini").is_file() for p in present):  # the split folder itself
        return f"; {root} holds sequences: it is a split folder, pass its parent {root.parent}"
    names = ", ".join(p.name for p in present)
    return f" (found: {names})" if names else ""


class MOTChallengeDataset:
    """The sequences of one split of a MOTChallenge-layout data set.

    ``benchmark`` is the rule set, whose :class:`~unitrack_env.datasets.mot_layouts.MOTLayout`
    says where the split's folders are and which file lists its sequences; ``detections`` is
    ``"public"`` (``det/det.txt``) or a folder of ``<sequence>.txt`` (or
    ``<sequence>/det/det.txt``) files. A benchmark without public detections (DanceTrack,
    SportsMOT) takes the folder given, else ``<root>/detections/<split>/``
    (:data:`DETECTIONS_FOLDER`, where the embedded default ships its), else refuses.
    """

    def __init__(
        self,
        root: str | Path,
        benchmark: str,
        split: str = "train",
        detections: str | Path | None = "public",
        class_map: ClassMap | None = None,
    ) -> None:
        self.root = Path(root)
        #: The data's class map (None: MOTChallenge's pedestrian rules).
        self.class_map = class_map
        self.benchmark = benchmark
        self.split = split
        if benchmark not in BENCHMARKS:
            raise ValueError(f"unknown benchmark '{benchmark}'; valid: {sorted(BENCHMARKS)}")
        self.layout: MOTLayout = LAYOUTS[benchmark]
        self.split_dir = self.layout.split_dir(self.root, split)
        if not self.split_dir.is_dir():
            rel = self.split_dir.relative_to(self.root)
            splits = "/ and ".join(str(self.layout.split_dir(Path(), s)) for s in
                                   self.layout.splits) + "/"
            raise DataFormatError(
                self.split_dir,
                f"split folder missing; root= should be the benchmark folder that holds "
                f"{splits}{_root_hint(self.root, rel, benchmark)}",
            )
        self.sequence_names = self._sequence_names()
        check_signature(benchmark, self.split_dir, self.sequence_names)
        self.detections = self._detections_source(detections)
        if self.detections != "public" and Path(self.detections).is_dir():
            stray = sorted(p.name for p in Path(self.detections).glob("*.txt")
                           if p.stem not in self.sequence_names)
            if stray:  # a misspelt name leaves its sequence without detections
                warnings.warn(f"{self.detections}: {', '.join(stray)} match no sequence of "
                              f"{self.split_dir} and are not read", stacklevel=2)

    def _sequence_names(self) -> list[str]:
        """The split's sequences, in its seqmap's order where there is one, else sorted.

        As TrackEval reads them: a layout's seqmap, when the file exists; else every folder
        with a seqinfo.ini or img1/.
        """
        seqmap = self.layout.seqmap_path(self.root, self.split)
        if seqmap is not None and seqmap.is_file():
            names = read_seqmap(seqmap)
            for line, name in names:
                if not (self.split_dir / name).is_dir():
                    raise DataFormatError(seqmap, f"lists '{name}', which has no folder in "
                                                  f"{self.split_dir}", line=line)
            return list(dict.fromkeys(name for _, name in names))
        names = sorted(
            p.name for p in self.split_dir.iterdir()
            if p.is_dir() and ((p / "seqinfo.ini").exists() or (p / "img1").is_dir())
        )
        if not names:
            raise DataFormatError(self.split_dir, "contains no sequence folders with seqinfo.ini")
        return names

    def _detections_source(self, detections: str | Path | None) -> str | Path:
        """``detections``, or where a benchmark without public detections finds them."""
        if self.layout.public_detections:
            return "public" if detections is None else detections
        if detections not in (None, "public"):
            return detections
        folder = self.root / DETECTIONS_FOLDER.format(split=self.split)
        if folder.is_dir():
            return folder
        example = folder / f"{self.sequence_names[0]}.txt"
        raise DataFormatError(
            example, f"{self.benchmark} ships no public detections and none were found here "
                     "(the first file expected): pass detections= (CLI: --detections), a folder "
                     "with one <sequence>.txt per sequence in det.txt format "
                     f"(frame,-1,x,y,w,h,score), or put such files in "
                     f"{DETECTIONS_FOLDER.format(split=self.split)}/ under root=")

    def __len__(self) -> int:
        return len(self.sequence_names)

    def detection_path(self, name: str) -> Path:
        """Return the detection file used for sequence ``name``."""
        if self.detections == "public":
            return self.split_dir / name / "det" / "det.txt"
        folder = Path(self.detections)
        if not folder.is_dir():
            raise DataFormatError(folder, "detections folder not found (detections= takes "
                                          "'public' or a folder of <sequence>.txt files)")
        for candidate in (folder / f"{name}.txt", folder / name / "det" / "det.txt"):
            if candidate.is_file():
                return candidate
        raise DataFormatError(
            folder / f"{name}.txt", f"no detection file for sequence '{name}' in {folder}"
        )

    def has_ground_truth(self, name: str) -> bool:
        """Whether sequence ``name`` ships a ``gt/gt.txt``."""
        return (self.split_dir / name / "gt" / "gt.txt").is_file()

    def load(self, name: str, *, check_frames: bool = True) -> MOTSequence:
        """Read one sequence's files (``check_frames``: every frame image must exist)."""
        if name not in self.sequence_names:
            raise UnknownSequenceError(
                f"no sequence '{name}' in {self.split_dir}; available: "
                f"{', '.join(self.sequence_names)}"
            )
        seq_dir = self.split_dir / name
        info = read_seqinfo(seq_dir, self.layout.frame_digits)
        if info.name != name:
            warnings.warn(
                f"{seq_dir / 'seqinfo.ini'}: name={info.name} differs from the folder name "
                f"'{name}'; using the folder name", stacklevel=2,
            )
        if check_frames:
            image_dir = seq_dir / info.image_dir
            if not image_dir.is_dir():
                raise DataFormatError(image_dir, "image folder missing (seqinfo.ini imDir)")
            present = {p.name for p in image_dir.iterdir()}
            for frame in range(1, info.length + 1):
                path = info.frame_path(frame)
                if path.name not in present:
                    other = sorted(p for p in present if Path(p).stem == path.stem)
                    hint = (f"; the folder holds {other[0]}: is seqinfo.ini imExt right?"
                            if other else "")
                    raise DataFormatError(
                        path, f"missing frame {frame} of {info.length} (seqinfo.ini "
                              f"seqLength){hint}")
        detections = read_detections(self.detection_path(name), info.length, self.class_map)
        gt_path = seq_dir / "gt" / "gt.txt"
        ground_truth = (
            read_ground_truth(gt_path, self.benchmark, info.length, self.class_map)
            if gt_path.is_file() else None
        )
        return MOTSequence(info, detections, ground_truth)
