"""Reader for BDD100K box tracking: one JSON list of frames per video (Scalabel format).

``<root>/labels/box_track_20/<split>/`` holds ``*.json`` files (every one is read; the
sequence is the file's stem, as TrackEval names it). Each file is a list of frames with
``frameIndex`` (from 0; TrackEval's ``index`` is read too) and ``labels``; a label has ``id``,
``category``, ``box2d`` (``x1 y1 x2 y2``) and ``attributes`` (``crowd``, or TrackEval's
``Crowd``: a ground-truth box that is an ignore region). Results are the same
layout with a ``score`` per label. Frames are ``<root>/images/track/<split>/<video>/
<video>-0000001.jpg...`` (``<video>`` the frames' ``videoName``, numbered from 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from unitrack_env.datasets.limits import (
    MAX_FRAMES,
    MAX_VIDEO_JSON_BYTES,
    check_image_size,
    image_size,
    load_json_limited,
)
from unitrack_env.errors import DataFormatError, UnknownSequenceError

#: BDD100K's 8 evaluated classes, in TrackEval's order; ids in rows are 1 + the index.
CLASSES: tuple[str, ...] = ("pedestrian", "rider", "car", "bus", "truck", "train",
                            "motorcycle", "bicycle")
#: Ground-truth categories TrackEval turns into ignore regions (as crowd boxes).
DISTRACTORS: tuple[str, ...] = ("other person", "trailer", "other vehicle")
#: BDD100K's super-categories (TrackEval's), each the detection average of its classes.
SUPER_CATEGORIES: dict[str, tuple[str, ...]] = {
    "HUMAN": ("pedestrian", "rider"), "VEHICLE": ("car", "truck", "bus", "train"),
    "BIKE": ("motorcycle", "bicycle")}
#: Where the split folders are under the root.
LABELS = Path("labels") / "box_track_20"
#: Where the frames of each video are under the root (``<split>/<video>/``).
IMAGES = Path("images") / "track"
#: Where the user's detections are looked for under the root when ``detections=`` is not given.
DEFAULT_DETECTIONS = Path("detections") / "box_track_20"
_BOX = ("x1", "y1", "x2", "y2")


@dataclass(frozen=True)
class BDDLabel:
    """One box: its id (as written), category, ``x1 y1 x2 y2``, crowd flag and score."""

    ident: str
    category: str
    box: tuple[float, float, float, float]
    crowd: bool
    score: float


def _label(raw: Any, where: str, categories: tuple[str, ...]) -> BDDLabel:
    """One label checked field by field; ``where`` names it in messages."""
    if not isinstance(raw, dict):
        raise ValueError(f"{where}: a label must be an object")
    ident = raw.get("id")
    if not isinstance(ident, (str, int)) or isinstance(ident, bool):
        raise ValueError(f"{where}.id: a string or integer is required, got {ident!r}")
    category = raw.get("category")
    if category not in categories:
        raise ValueError(f"{where}.category: {category!r} is not one of {list(categories)}")
    box = raw.get("box2d")
    if not isinstance(box, dict):
        raise ValueError(f"{where}.box2d: an object with {list(_BOX)} is required")
    values = []
    for key in _BOX:
        value = box.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value):
            raise ValueError(f"{where}.box2d.{key}: a finite number is required, got {value!r}")
        values.append(float(value))
    attributes = raw.get("attributes") or {}
    if not isinstance(attributes, dict):
        raise ValueError(f"{where}.attributes: an object is required")
    score = raw.get("score", 1.0)
    if isinstance(score, bool) or not isinstance(score, (int, float)) \
            or not math.isfinite(score):
        raise ValueError(f"{where}.score: a finite number is required, got {score!r}")
    return BDDLabel(str(ident), category, (values[0], values[1], values[2], values[3]),
                    bool(attributes.get("crowd", attributes.get("Crowd", False))), float(score))


def load_bdd_json(path: Path) -> list[Any]:
    """The JSON list of frames of ``path`` (size-limited); DataFormatError names the file."""
    try:
        data = load_json_limited(path, MAX_VIDEO_JSON_BYTES, "BDD100K video's JSON")
    except (UnicodeDecodeError, ValueError) as exc:
        if isinstance(exc, DataFormatError):
            raise
        raise DataFormatError(path, f"unreadable JSON ({exc})") from None
    if not isinstance(data, list):
        raise DataFormatError(path, "a JSON list of frames is required")
    return data


def bdd_frames(data: list[Any], path: Path, *, results: bool = False,
               length: int | None = None) -> list[list[BDDLabel]]:
    """The labels of each frame of ``data`` (:func:`load_bdd_json` of ``path``).

    Frames from 0; missing frames are empty. Ground truth (``results=False``) may hold the 8
    classes and the distractor categories; results only the 8 classes, with frames inside
    ``length`` when it is given. DataFormatError names the file and the frame / label / field
    of a problem.
    """
    categories = CLASSES if results else CLASSES + DISTRACTORS
    frames: dict[int, list[BDDLabel]] = {}
    for position, frame in enumerate(data):
        where = f"frame [{position}]"
        try:
            if not isinstance(frame, dict):
                raise ValueError(f"{where}: a frame must be an object")
            index = frame.get("frameIndex", frame.get("index"))
            if isinstance(index, bool) or not isinstance(index, int) or index < 0:
                raise ValueError(f"{where}.frameIndex: an integer >= 0 is required, "
                                 f"got {index!r}")
            limit = length if length is not None else MAX_FRAMES
            if index >= limit:
                raise ValueError(f"{where}.frameIndex: {index} is beyond the sequence's "
                                 f"{limit} frames")
            if index in frames:
                raise ValueError(f"{where}.frameIndex: frame {index} appears twice")
            labels = frame.get("labels") or []
            if not isinstance(labels, list):
                raise ValueError(f"{where}.labels: a list is required")
            frames[index] = [_label(raw, f"{where}.labels[{i}]", categories)
                             for i, raw in enumerate(labels)]
        except ValueError as exc:
            raise DataFormatError(path, str(exc)) from None
    count = length if length is not None else (max(frames) + 1 if frames else 0)
    return [frames.get(t, []) for t in range(count)]


def read_bdd_frames(path: Path, *, results: bool = False,
                    length: int | None = None) -> list[list[BDDLabel]]:
    """:func:`bdd_frames` of the file ``path``."""
    return bdd_frames(load_bdd_json(path), path, results=results, length=length)


def video_name(data: list[Any], path: Path) -> str:
    """The ``videoName`` the frames of ``data`` state (the file's stem when none does).

    It names the folder of the video's frames, so it must be a plain folder name, the same
    in every frame.
    """
    names = {frame.get("videoName") for frame in data
             if isinstance(frame, dict) and "videoName" in frame}
    if not names:
        return path.stem
    if len(names) > 1:
        raise DataFormatError(path, f"frames name {len(names)} videos "
                              f"({', '.join(sorted(map(str, names))[:3])}); one video per file",
                              field="videoName")
    name = names.pop()
    if not isinstance(name, str) or not name.strip(". ") or any(c in name for c in "/\\\0"):
        raise DataFormatError(path, f"{name!r} is not a plain folder name", field="videoName")
    return name


@dataclass(frozen=True)
class BDDSequence:
    """One video: name, frame folder, length, image size, detections and ground truth."""

    name: str
    image_dir: Path
    video: str
    length: int
    size: tuple[int, int]
    detections: list[list[BDDLabel]]
    ground_truth: list[list[BDDLabel]]

    def frame_path(self, frame: int) -> Path:
        """The image of 0-based ``frame`` (``<video>-<frame + 1, 7 digits>.jpg``)."""
        return self.image_dir / frame_name(self.video, frame)


def frame_name(video: str, frame: int) -> str:
    """BDD100K's file name of 0-based ``frame`` of ``video``."""
    return f"{video}-{frame + 1:07d}.jpg"


class BDD100KDataset:
    """The videos of one split: ``<root>/labels/box_track_20/<split>/*.json``.

    Frames (only to play, not to score) are ``<root>/images/track/<split>/<video>/``;
    detections the user's ``<detections>/<sequence>.json`` in the result format (default
    ``<root>/detections/box_track_20/<split>``).
    """

    def __init__(self, root: str | Path, split: str = "val",
                 detections: str | Path | None = None) -> None:
        self.root = Path(root)
        self.split = split
        self.split_dir = self.root / LABELS / split
        if not self.split_dir.is_dir():
            raise DataFormatError(self.split_dir, "missing: BDD100K's box-track labels of "
                                  f"split {split!r} are expected there")
        files = sorted(self.split_dir.glob("*.json"))
        if not files:
            raise DataFormatError(self.split_dir, "holds no *.json file")
        self.files = {f.stem: f for f in files}
        self.sequence_names = list(self.files)
        self.lengths: dict[str, int] = {}
        self.videos: dict[str, str] = {}
        for name, path in self.files.items():
            data = load_bdd_json(path)
            self.lengths[name] = len(bdd_frames(data, path))
            self.videos[name] = video_name(data, path)
        self.detections = (Path(detections) if detections is not None
                           else self.root / DEFAULT_DETECTIONS / split)

    def ground_truth_path(self, name: str) -> Path:
        """The JSON file of ``name``."""
        if name not in self.files:
            raise UnknownSequenceError(f"unknown BDD100K sequence {name!r} in {self.split_dir}")
        return self.files[name]

    def image_dir(self, name: str) -> Path:
        """``<root>/images/track/<split>/<video>`` of sequence ``name``."""
        self.ground_truth_path(name)
        return self.root / IMAGES / self.split / self.videos[name]

    def frame_path(self, name: str, frame: int) -> Path:
        """The image of 0-based ``frame`` of sequence ``name``."""
        return self.image_dir(name) / frame_name(self.videos[name], frame)

    def detection_path(self, name: str) -> Path:
        """``<detections>/<name>.json``."""
        return self.detections / f"{name}.json"

    def check_images(self, name: str) -> None:
        """Refuse a sequence whose frame folder is missing (scoring needs none; playing does)."""
        folder = self.image_dir(name)
        if not folder.is_dir():
            raise DataFormatError(folder, f"missing: the frames of video {self.videos[name]!r} "
                                  f"({frame_name(self.videos[name], 0)}, ...) are needed to "
                                  "play it; `unitrack score` scores result files without them")

    def load(self, name: str, *, check_frames: bool = True) -> BDDSequence:
        """Read one video (``check_frames``: every frame image must exist)."""
        self.check_images(name)
        length = self.lengths[name]
        if check_frames:
            for frame in range(length):
                if not self.frame_path(name, frame).is_file():
                    raise DataFormatError(self.frame_path(name, frame),
                                          f"missing frame {frame + 1} of {length}")
        first = self.frame_path(name, 0)
        kind, size = image_size(first)
        if size is None:
            raise DataFormatError(first, f"not a JPEG frame with a readable size ({kind})")
        check_image_size(first, size)
        gt = read_bdd_frames(self.files[name])
        detections = read_bdd_frames(self.detection_path(name), results=True, length=length)
        return BDDSequence(name, self.image_dir(name), self.videos[name], length, size,
                           detections, gt)
