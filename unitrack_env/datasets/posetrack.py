"""Reader and writer of PoseTrack 2018 JSON (ground truth, results and pose detections).

Layout read, exactly as the benchmark ships it (``root`` is the folder holding
``posetrack_data/``, or ``posetrack_data/`` itself)::

    posetrack_data/annotations/{train,val}/<sequence>.json    one file per video
    posetrack_data/images/{train,val,test}/<sequence>/000000.jpg ...

A sequence file is COCO-like (PoseTrack 2018 release; field meanings from poseval's
``convert.py``, leonid-pishchulin/poseval):

* ``images``: one entry per frame: ``id`` (``1`` + 6-digit video id + 4-digit frame index,
  e.g. ``10034180000``), ``file_name`` (``images/val/<sequence>/000000.jpg``, relative to
  ``posetrack_data/``), ``is_labeled``, ``nframes``, ``frame_id``, ``vid_id``, optional
  ``width``/``height``, optional ``ignore_regions_x``/``ignore_regions_y`` (lists of polygons,
  one list of x and one of y coordinates per polygon) and others (``has_no_densepose``,
  ``mask_file``), which are kept as read.
* ``annotations``: one per person and labelled frame: ``image_id``, ``track_id`` (0-based per
  video), ``keypoints`` (17 x ``(x, y, v)`` flattened, COCO order; an unannotated keypoint is
  ``0, 0, 0``), ``bbox_head`` ``(x, y, w, h)`` (the PCKh reference), ``bbox``, ``scores``
  (per-keypoint scores, empty in ground truth), ``id``, ``category_id``, ``iscrowd``,
  ``num_keypoints``.
* ``categories``: one ``person`` category whose ``keypoints`` are
  :data:`POSETRACK_KEYPOINTS` (``head_bottom``/``head_top`` sit in COCO's eye slots; the ear
  slots are never annotated) and whose ``skeleton`` is :data:`POSETRACK_SKELETON`.

Result files (what a tracker submits) use the same schema with ``track_id`` and ``scores``
per person and the ``images`` of the ground-truth file in the same order. Pose detections
(the observations of :class:`~unitrack_env.envs.posetrack.PoseTrackEnv`) are stored in that
result format without ``track_id``.

Coordinates are kept exactly as written (PoseTrack keypoints are floating-point pixels); the
reader never shifts them. :func:`video_to_json` writes back every field read, so
``video_to_json(read_posetrack_json(p))`` equals the file's JSON (numbers compare equal;
integral floats are written as integers like the official files).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from unitrack_env.errors import DataFormatError, UnknownSequenceError
from unitrack_env.io import atomic_write_text

POSETRACK_KEYPOINTS: tuple[str, ...] = (
    "nose", "head_bottom", "head_top", "left_ear", "right_ear",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist",
    "right_wrist", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle",
    "right_ankle",
)
"""The 17 PoseTrack 2018 keypoints in file order (categories[0]["keypoints"])."""

NUM_KEYPOINTS: int = len(POSETRACK_KEYPOINTS)

POSETRACK_SKELETON: tuple[tuple[int, int], ...] = (
    (16, 14), (14, 12), (17, 15), (15, 13), (12, 13), (6, 12), (7, 13), (6, 7), (6, 8),
    (7, 9), (8, 10), (9, 11), (2, 3), (1, 2), (1, 3), (2, 4), (3, 5), (4, 6), (5, 7),
)
"""Limbs as 1-based keypoint pairs, as in the release's ``categories[0]["skeleton"]``."""

#: The ``categories`` entry written into every file.
PERSON_CATEGORY: dict[str, Any] = {
    "supercategory": "person",
    "id": 1,
    "name": "person",
    "keypoints": list(POSETRACK_KEYPOINTS),
    "skeleton": [list(pair) for pair in POSETRACK_SKELETON],
}

#: Splits of the release; ``test`` ships images only.
SPLITS: tuple[str, ...] = ("train", "val", "test")
#: Sub-folder holding the benchmark files.
DATA_FOLDER = "posetrack_data"
#: Image id of frame ``k`` of video ``v``: ``IMAGE_ID_BASE + v * FRAMES_PER_VIDEO + k``.
IMAGE_ID_BASE = 10_000_000_000
#: Frame slots per video in the image id scheme.
FRAMES_PER_VIDEO = 10_000
#: Annotation id of person ``p`` of image ``i``: ``i * PERSONS_PER_IMAGE + p``.
PERSONS_PER_IMAGE = 100

_IMAGE_FIELDS = ("id", "file_name", "is_labeled", "nframes", "frame_id", "vid_id",
                 "ignore_regions_x", "ignore_regions_y")
_PERSON_FIELDS = ("image_id", "keypoints", "track_id", "scores", "score", "bbox", "bbox_head",
                  "id")


@dataclass
class PoseTrackImage:
    """One frame entry of ``images``.

    Attributes:
        id: the image id annotations refer to.
        file_name: path relative to ``posetrack_data/``.
        is_labeled: whether the frame is annotated (None when the entry does not say).
        nframes: the video's frame count as declared (may exceed the frames present).
        frame_id: PoseTrack's frame id (equal to ``id`` in the release).
        vid_id: the 6-digit video id.
        ignore_regions: polygons, each ``(k, 2)`` float64 ``(x, y)``, where annotations are
            missing on purpose (crowds); evaluation drops keypoints inside them.
        extra: every other field, as read.
    """

    id: int
    file_name: str
    is_labeled: bool | None = None
    nframes: int | None = None
    frame_id: int | None = None
    vid_id: str | None = None
    ignore_regions: tuple[np.ndarray, ...] = ()
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def frame_index(self) -> int:
        """The 0-based frame index from the file name (``000012.jpg`` -> 12)."""
        return int(Path(self.file_name).stem)


@dataclass
class PoseTrackPerson:
    """One person (annotation) in one frame.

    Attributes:
        image_id: the frame.
        keypoints: ``(17, 3)`` float64 ``(x, y, v)``; ``(0, 0, 0)`` marks an absent keypoint.
        track_id: identity (None in detection files).
        scores: ``(17,)`` per-keypoint scores, or None when the file has none (ground truth
            writes an empty list, kept as an empty array).
        score: pose score, if given.
        bbox: ``(x, y, w, h)``, if given.
        bbox_head: ``(x, y, w, h)`` head box, the PCKh reference, if given.
        id: annotation id, if given.
        extra: every other field, as read.
    """

    image_id: int
    keypoints: np.ndarray
    track_id: int | None = None
    scores: np.ndarray | None = None
    score: float | None = None
    bbox: tuple[float, float, float, float] | None = None
    bbox_head: tuple[float, float, float, float] | None = None
    id: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def annotated(self) -> np.ndarray:
        """``(17,)`` bool: keypoints that are not ``(0, 0, 0)`` (poseval's rule)."""
        return ~np.all(self.keypoints == 0.0, axis=1)


@dataclass
class PoseTrackVideo:
    """The content of one sequence file.

    Attributes:
        images: frame entries in file order.
        people: per image (same order), its persons in file order.
        categories: the ``categories`` list as read.
        extra: other top-level fields, as read.
    """

    images: list[PoseTrackImage]
    people: list[list[PoseTrackPerson]]
    categories: list[dict[str, Any]] = field(default_factory=lambda: [dict(PERSON_CATEGORY)])
    extra: dict[str, Any] = field(default_factory=dict)

    def index_of(self, image_id: int) -> int:
        """Return the position of image ``image_id`` in :attr:`images`."""
        for k, image in enumerate(self.images):
            if image.id == image_id:
                return k
        raise KeyError(image_id)


# --------------------------------------------------------------------------- reading
def _require(path: Path, ok: bool, message: str, fld: str) -> None:
    if not ok:
        raise DataFormatError(path, message, field=fld)


def _int(path: Path, value: Any, fld: str) -> int:
    """A JSON integer (an integral float such as ``3.0`` is accepted), else a clear error."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (
            isinstance(value, float) and not value.is_integer()):
        raise DataFormatError(path, f"must be an integer, got {type(value).__name__} "
                                    f"{json.dumps(value)[:60]}", field=fld)
    return int(value)


def _opt_int(path: Path, entry: dict[str, Any], key: str, where: str) -> int | None:
    value = entry.get(key)
    return None if value is None else _int(path, value, f"{where}.{key}")


def _float(path: Path, value: Any, fld: str) -> float:
    """A finite JSON number, else a clear error."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise DataFormatError(path, f"must be a finite number, got {type(value).__name__} "
                                    f"{json.dumps(value)[:60]}", field=fld)
    return float(value)


def _box(path: Path, value: Any, fld: str) -> tuple[float, float, float, float] | None:
    if value is None:
        return None
    try:
        box = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise DataFormatError(path, f"expected 4 numbers, got {value!r}", field=fld) from None
    _require(path, len(box) == 4, f"expected 4 numbers (x, y, w, h), got {len(box)}", fld)
    return box  # type: ignore[return-value]


def _keypoint_names(path: Path, categories: list[dict[str, Any]]) -> None:
    for k, category in enumerate(categories):
        _require(path, isinstance(category, dict),
                 f"must be an object like {{'id': 1, 'name': 'person', 'keypoints': [...]}}, got "
                 f"{type(category).__name__} {json.dumps(category)[:60]}", f"categories[{k}]")
    if not categories:
        return
    names = categories[0].get("keypoints", ())
    _require(path, isinstance(names, list) and all(isinstance(n, str) for n in names),
             "must be a list of keypoint names", "categories[0].keypoints")
    names = tuple(names)
    if names and names != POSETRACK_KEYPOINTS:
        raise DataFormatError(
            path, f"keypoints {list(names)} differ from the PoseTrack 2018 order "
                  f"{list(POSETRACK_KEYPOINTS)}", field="categories[0].keypoints")


def _parse_image(path: Path, k: int, entry: Any) -> PoseTrackImage:
    where = f"images[{k}]"
    _require(path, isinstance(entry, dict), "must be an object", where)
    for key in ("id", "file_name"):
        _require(path, key in entry, f"missing '{key}'", f"{where}.{key}")
    xs = entry.get("ignore_regions_x") or []
    ys = entry.get("ignore_regions_y") or []
    for key, value in (("ignore_regions_x", xs), ("ignore_regions_y", ys)):
        _require(path, isinstance(value, list) and all(isinstance(p, list) for p in value),
                 "must be a list of polygons (lists of numbers)", f"{where}.{key}")
    _require(path, len(xs) == len(ys), "ignore_regions_x and ignore_regions_y differ in length",
             f"{where}.ignore_regions_x")
    regions = []
    for r, (px, py) in enumerate(zip(xs, ys, strict=True)):
        _require(path, len(px) == len(py), f"polygon {r} has {len(px)} x but {len(py)} y",
                 f"{where}.ignore_regions_x")
        try:
            regions.append(np.column_stack([np.asarray(px, np.float64).reshape(-1),
                                            np.asarray(py, np.float64).reshape(-1)]))
        except (TypeError, ValueError):
            raise DataFormatError(path, f"polygon {r} holds something else than numbers",
                                  field=f"{where}.ignore_regions_x") from None
    try:
        stem_ok = Path(str(entry["file_name"])).stem.isdigit()
    except TypeError:
        stem_ok = False
    _require(path, stem_ok, f"file name {entry['file_name']!r} is not '<frame>.jpg'",
             f"{where}.file_name")
    return PoseTrackImage(
        id=_int(path, entry["id"], f"{where}.id"),
        file_name=str(entry["file_name"]),
        is_labeled=None if entry.get("is_labeled") is None else bool(entry["is_labeled"]),
        nframes=_opt_int(path, entry, "nframes", where),
        frame_id=_opt_int(path, entry, "frame_id", where),
        vid_id=None if entry.get("vid_id") is None else str(entry["vid_id"]),
        ignore_regions=tuple(regions),
        extra={k2: v for k2, v in entry.items()
               if k2 not in _IMAGE_FIELDS or (k2.startswith("ignore_") and not regions)},
    )


def _parse_person(path: Path, k: int, entry: Any) -> PoseTrackPerson:
    where = f"annotations[{k}]"
    _require(path, isinstance(entry, dict), "must be an object", where)
    for key in ("image_id", "keypoints"):
        _require(path, key in entry, f"missing '{key}'", f"{where}.{key}")
    _require(path, isinstance(entry["keypoints"], list),
             f"must be a list of {3 * NUM_KEYPOINTS} numbers (17 x (x, y, v)), got "
             f"{type(entry['keypoints']).__name__} {json.dumps(entry['keypoints'])[:60]}",
             f"{where}.keypoints")
    try:
        flat = np.asarray(entry["keypoints"], dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise DataFormatError(path, "keypoints must be numbers", field=f"{where}.keypoints"
                              ) from None
    _require(path, flat.size == 3 * NUM_KEYPOINTS,
             f"has {flat.size} values, expected {3 * NUM_KEYPOINTS} (17 x (x, y, v))",
             f"{where}.keypoints")
    _require(path, bool(np.all(np.isfinite(flat))), "has NaN or infinite values",
             f"{where}.keypoints")
    scores = entry.get("scores")
    score_arr = None
    if scores is not None:
        try:
            score_arr = np.asarray(scores, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise DataFormatError(path, f"must be a list of numbers, got {str(scores)[:60]}",
                                  field=f"{where}.scores") from None
        _require(path, score_arr.size in (0, NUM_KEYPOINTS),
                 f"has {score_arr.size} scores, expected 0 or {NUM_KEYPOINTS}", f"{where}.scores")
    if entry.get("category_id") is not None:
        _int(path, entry["category_id"], f"{where}.category_id")
    return PoseTrackPerson(
        image_id=_int(path, entry["image_id"], f"{where}.image_id"),
        keypoints=flat.reshape(NUM_KEYPOINTS, 3),
        track_id=_opt_int(path, entry, "track_id", where),
        scores=score_arr,
        score=None if entry.get("score") is None else _float(path, entry["score"],
                                                                 f"{where}.score"),
        bbox=_box(path, entry.get("bbox"), f"{where}.bbox"),
        bbox_head=_box(path, entry.get("bbox_head"), f"{where}.bbox_head"),
        id=_opt_int(path, entry, "id", where),
        extra={k2: v for k2, v in entry.items() if k2 not in _PERSON_FIELDS},
    )


def parse_posetrack(data: Any, path: str | os.PathLike = "<json>") -> PoseTrackVideo:
    """Parse the JSON object of one PoseTrack 2018 sequence file.

    Raises:
        DataFormatError: a missing or malformed field (the message names it), an annotation
            of an unknown image, or keypoints in another order than PoseTrack 2018's.
    """
    path = Path(path)
    _require(path, isinstance(data, dict), "top level must be a JSON object", "<root>")
    _require(path, isinstance(data.get("images"), list), "missing 'images' list", "images")
    annotations = data.get("annotations", [])
    _require(path, isinstance(annotations, list), "'annotations' must be a list", "annotations")
    categories = data.get("categories", [dict(PERSON_CATEGORY)])
    _require(path, isinstance(categories, list), "'categories' must be a list", "categories")
    _keypoint_names(path, categories)
    images = [_parse_image(path, k, entry) for k, entry in enumerate(data["images"])]
    position = {image.id: k for k, image in enumerate(images)}
    if len(position) != len(images):
        raise DataFormatError(path, "duplicate image ids", field="images")
    people: list[list[PoseTrackPerson]] = [[] for _ in images]
    for k, entry in enumerate(annotations):
        person = _parse_person(path, k, entry)
        if person.image_id not in position:
            raise DataFormatError(path, f"refers to image_id {person.image_id}, which is not in "
                                        "'images'", field=f"annotations[{k}].image_id")
        people[position[person.image_id]].append(person)
    extra = {k: v for k, v in data.items() if k not in ("images", "annotations", "categories")}
    return PoseTrackVideo(images, people, categories, extra)


def read_posetrack_json(path: str | os.PathLike) -> PoseTrackVideo:
    """Read one PoseTrack 2018 sequence file (ground truth, results or detections).

    Raises:
        DataFormatError: unreadable or invalid JSON, or a schema error (see
            :func:`parse_posetrack`).
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataFormatError(path, "missing") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DataFormatError(path, f"not readable JSON ({err})") from err
    return parse_posetrack(data, path)


# --------------------------------------------------------------------------- writing
def _num(value: float) -> int | float:
    """A JSON number: integral values as int (like the official files), others as float."""
    value = float(value)
    return int(value) if value.is_integer() else value


def _image_json(image: PoseTrackImage) -> dict[str, Any]:
    out: dict[str, Any] = dict(image.extra)
    out["id"] = image.id
    out["file_name"] = image.file_name
    for key in ("is_labeled", "nframes", "frame_id", "vid_id"):
        if getattr(image, key) is not None:
            out[key] = getattr(image, key)
    if image.ignore_regions:
        out["ignore_regions_x"] = [[_num(v) for v in poly[:, 0]] for poly in image.ignore_regions]
        out["ignore_regions_y"] = [[_num(v) for v in poly[:, 1]] for poly in image.ignore_regions]
    return out


def _person_json(person: PoseTrackPerson) -> dict[str, Any]:
    out: dict[str, Any] = dict(person.extra)
    out["image_id"] = person.image_id
    out["keypoints"] = [_num(v) for v in person.keypoints.reshape(-1)]
    if person.track_id is not None:
        out["track_id"] = person.track_id
    if person.scores is not None:
        out["scores"] = [_num(v) for v in person.scores]
    if person.score is not None:
        out["score"] = _num(person.score)
    if person.bbox is not None:
        out["bbox"] = [_num(v) for v in person.bbox]
    if person.bbox_head is not None:
        out["bbox_head"] = [_num(v) for v in person.bbox_head]
    if person.id is not None:
        out["id"] = person.id
    return out


def video_to_json(video: PoseTrackVideo) -> dict[str, Any]:
    """Return the JSON object of a sequence file (the inverse of :func:`parse_posetrack`)."""
    out: dict[str, Any] = dict(video.extra)
    out["images"] = [_image_json(image) for image in video.images]
    out["annotations"] = [_person_json(p) for persons in video.people for p in persons]
    out["categories"] = video.categories
    return out


def write_posetrack_json(path: str | os.PathLike, video: PoseTrackVideo) -> None:
    """Write a sequence file atomically (compact JSON, like the release)."""
    atomic_write_text(path, json.dumps(video_to_json(video), separators=(",", ":")))


def image_id(video_number: int, frame_index: int) -> int:
    """Return PoseTrack's image id of frame ``frame_index`` of video ``video_number``."""
    return IMAGE_ID_BASE + int(video_number) * FRAMES_PER_VIDEO + int(frame_index)


def video_number(sequence: str) -> int | None:
    """Return the numeric video id of a sequence name (``003418_mpii_test`` -> 3418)."""
    head = sequence.split("_", 1)[0]
    return int(head) if head.isdigit() else None


# --------------------------------------------------------------------------- data set
@dataclass(frozen=True)
class PoseTrackSequence:
    """One video of a split.

    Attributes:
        name: the sequence name (file stem / image folder).
        split: ``train``, ``val`` or ``test``.
        images: frame entries in order (from the annotation file, or made up from the image
            files for splits without annotations).
        frame_paths: the image file of every entry.
        ground_truth: the annotation file's content, or None (test split).
        image_size: ``(width, height)``.
        annotation_path: the annotation file, or None.
    """

    name: str
    split: str
    images: tuple[PoseTrackImage, ...]
    frame_paths: tuple[Path, ...]
    ground_truth: PoseTrackVideo | None
    image_size: tuple[int, int]
    annotation_path: Path | None

    @property
    def length(self) -> int:
        """Number of frames (steps)."""
        return len(self.images)


def locate_data_folder(root: str | os.PathLike) -> Path:
    """Return the ``posetrack_data`` folder given it or the folder that holds it."""
    root = Path(root)
    if (root / DATA_FOLDER).is_dir():
        return root / DATA_FOLDER
    if (root / "images").is_dir() or (root / "annotations").is_dir():
        return root
    raise DataFormatError(root, f"neither holds '{DATA_FOLDER}/' nor is one (expected "
                                "annotations/<split>/*.json and images/<split>/<sequence>/)")


def images_from_files(sequence: str, split: str, paths: list[Path]) -> tuple[PoseTrackImage, ...]:
    """Make ``images`` entries for frame files that have no annotation file (test split).

    Ids follow the release's scheme (:func:`image_id`) when the sequence name starts with a
    numeric video id, else they count from :data:`IMAGE_ID_BASE`.
    """
    number = video_number(sequence)
    out = []
    for path in paths:
        index = int(path.stem)
        iid = image_id(number, index) if number is not None else IMAGE_ID_BASE + index
        out.append(PoseTrackImage(
            id=iid, file_name=f"images/{split}/{sequence}/{path.name}", is_labeled=False,
            nframes=len(paths), frame_id=iid,
            vid_id=f"{number:06d}" if number is not None else sequence,
        ))
    return tuple(out)


class PoseTrackDataset:
    """The sequences of one split of a PoseTrack 2018 folder.

    Args:
        root: the folder holding ``posetrack_data/`` (or that folder itself).
        split: ``train``, ``val`` or ``test``. A split with annotation files lists their
            sequences; a split without (test) lists the image folders.
    """

    def __init__(self, root: str | os.PathLike, split: str = "val") -> None:
        if split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}; got {split!r}")
        self.data_dir = locate_data_folder(root)
        self.split = split
        self.annotation_dir = self.data_dir / "annotations" / split
        self.image_dir = self.data_dir / "images" / split
        files = sorted(self.annotation_dir.glob("*.json")) if self.annotation_dir.is_dir() else []
        if files:
            self.sequence_names = [p.stem for p in files]
            self.annotated = True
        elif self.image_dir.is_dir():
            self.sequence_names = sorted(p.name for p in self.image_dir.iterdir() if p.is_dir())
            self.annotated = False
        else:
            self.sequence_names = []
            self.annotated = False
        if not self.sequence_names:
            raise DataFormatError(
                self.data_dir, f"no sequences for split '{split}' (looked for "
                               f"annotations/{split}/*.json and images/{split}/<sequence>/)")

    def has_ground_truth(self, name: str) -> bool:
        """Whether ``name`` has an annotation file."""
        return (self.annotation_dir / f"{name}.json").is_file()

    def _check(self, name: str) -> None:
        if name not in self.sequence_names:
            raise UnknownSequenceError(
                f"no PoseTrack sequence '{name}' in {self.data_dir} ({self.split}); "
                f"available: {', '.join(self.sequence_names)}")

    def sequence_length(self, name: str) -> int:
        """Number of frames of ``name`` (its ``images`` entries, or its image files)."""
        self._check(name)
        if self.has_ground_truth(name):
            return len(read_posetrack_json(self.annotation_dir / f"{name}.json").images)
        return len(self._image_files(name))

    def _image_files(self, name: str) -> list[Path]:
        folder = self.image_dir / name
        if not folder.is_dir():
            raise DataFormatError(folder, f"frames of '{name}' missing")
        files = sorted(p for p in folder.iterdir()
                       if p.suffix.lower() in (".jpg", ".jpeg", ".png") and p.stem.isdigit())
        if not files:
            raise DataFormatError(folder, "holds no '<frame>.jpg' images")
        return files

    def load(self, name: str) -> PoseTrackSequence:
        """Read one sequence: its frame entries, frame files and ground truth (if any).

        Raises:
            DataFormatError: a frame listed in the annotation file has no image file.
        """
        self._check(name)
        annotation = self.annotation_dir / f"{name}.json"
        if annotation.is_file():
            video = read_posetrack_json(annotation)
            images = tuple(video.images)
            paths = tuple(self._frame_path(annotation, name, image) for image in images)
        else:
            video, annotation = None, None
            files = self._image_files(name)
            images = images_from_files(name, self.split, files)
            paths = tuple(files)
        if not images:
            raise DataFormatError(annotation or self.image_dir / name, "has no frames")
        first = images[0]
        if "width" in first.extra and "height" in first.extra:
            size = (int(first.extra["width"]), int(first.extra["height"]))
        else:
            from unitrack_env.datasets.otb import read_image_size

            size = read_image_size(paths[0])
        return PoseTrackSequence(name, self.split, images, paths, video, size, annotation)

    def _frame_path(self, annotation: Path, name: str, image: PoseTrackImage) -> Path:
        path = self.data_dir / image.file_name
        if path.is_file():
            return path
        fallback = self.image_dir / name / Path(image.file_name).name
        if fallback.is_file():
            return fallback
        raise DataFormatError(annotation, f"lists frame {image.file_name!r} but neither {path} "
                                          f"nor {fallback} exists", field="images.file_name")
