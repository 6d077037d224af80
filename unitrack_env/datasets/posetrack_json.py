"""PoseTrack 2018 JSON in and out: strict parsing of a sequence file, and writing it back.

:func:`parse_posetrack` checks every field it keeps (a wrong type names the file and the
field); :func:`video_to_json` writes back every field read, so
``video_to_json(read_posetrack_json(p))`` equals the file's JSON.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from unitrack_env.datasets.limits import (
    MAX_VIDEO_JSON_BYTES,
    check_id,
    check_track_total,
    load_json_limited,
)
from unitrack_env.datasets.posetrack_records import (
    FRAMES_PER_VIDEO,
    IMAGE_ID_BASE,
    NUM_KEYPOINTS,
    PERSON_CATEGORY,
    POSETRACK_KEYPOINTS,
    PoseTrackImage,
    PoseTrackPerson,
    PoseTrackVideo,
)
from unitrack_env.errors import DataFormatError
from unitrack_env.io import atomic_write_text

_IMAGE_FIELDS = ("id", "file_name", "is_labeled", "nframes", "frame_id", "vid_id",
                 "ignore_regions_x", "ignore_regions_y")
_PERSON_FIELDS = ("image_id", "keypoints", "track_id", "scores", "score", "bbox", "bbox_head",
                  "id")


def _require(path: Path, ok: bool, message: str, fld: str) -> None:
    if not ok:
        raise DataFormatError(path, message, field=fld)


def _int(path: Path, value: Any, fld: str) -> int:
    """A JSON integer (an integral float such as ``3.0`` is accepted), else a clear error."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (
            isinstance(value, float) and not value.is_integer()):
        raise DataFormatError(path, f"must be an integer, got {type(value).__name__} "
                                    f"{json.dumps(value)[:60]}", field=fld)
    if not -2**63 <= value < 2**63:  # numpy (and the scorer) hold ids as int64
        raise DataFormatError(path, f"{json.dumps(value)[:60]} is out of range (int64)",
                              field=fld)
    return int(value)


def _opt_int(path: Path, entry: dict[str, Any], key: str, where: str) -> int | None:
    value = entry.get(key)
    return None if value is None else _int(path, value, f"{where}.{key}")


def _track_id(path: Path, entry: dict[str, Any], where: str) -> int | None:
    """A person's ``track_id``: None or an int in ``0..MAX_ID`` (ids of the result files)."""
    value = _opt_int(path, entry, "track_id", where)
    return None if value is None else check_id(value, path, field=f"{where}.track_id",
                                               what="track_id")


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
        track_id=_track_id(path, entry, where),
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

    DataFormatError names a missing or malformed field, an annotation of an unknown image, or
    keypoints in another order than PoseTrack 2018's.
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
    check_track_total(len({p.track_id for p in (q for ps in people for q in ps)
                           if p.track_id is not None}), path, what="track_ids",
                      field="annotations")
    extra = {k: v for k, v in data.items() if k not in ("images", "annotations", "categories")}
    return PoseTrackVideo(images, people, categories, extra)


def read_posetrack_json(path: str | os.PathLike) -> PoseTrackVideo:
    """Read one PoseTrack 2018 sequence file (ground truth, results or detections)."""
    path = Path(path)
    try:
        data = load_json_limited(path, MAX_VIDEO_JSON_BYTES, "PoseTrack file")
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
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

