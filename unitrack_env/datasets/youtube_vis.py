"""Reader and writer of YouTube-VIS 2019 (video instance segmentation) JSON files.

Format (Yang et al., "Video Instance Segmentation", ICCV 2019; the CodaLab page's definition,
restated in TrackEval's ``docs/YouTube-VIS-format.txt``), MS-COCO style: ``videos`` (``id``,
``width``, ``height``, ``length``, ``file_names``), ``categories``, and ``annotations`` with
``video_id``, ``category_id``, ``iscrowd`` and, per frame of the video, a segmentation (RLE or
polygons), area and box, None where the object is absent. Results are a list of ``{video_id,
category_id, segmentations, score}``; detections use that format (docs/envs/vis.md). The 2019
release's ``valid`` and ``test`` files have no annotations. A video is named by the folder of
its frames (the first component of its ``file_names``), as TrackEval names sequences.
"""

from __future__ import annotations

import json
import os
import sys
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from unitrack_env.datasets.limits import (
    MAX_SPLIT_JSON_BYTES,
    check_id,
    check_image_size,
    check_track_total,
    load_json_limited,
)
from unitrack_env.datasets.rle import check_rle
from unitrack_env.datasets.rle import mask_api as mask_utils
from unitrack_env.errors import DataFormatError
from unitrack_env.io import path_inside

#: Splits of the 2019 release.
SPLITS = ("train", "valid", "test")
#: Where frames are under the split folder.
IMAGE_FOLDER = "JPEGImages"
#: Frame rate of the annotated frames (YouTube-VIS annotates every 5th frame of 30 fps video).
FRAME_RATE = 6.0


def to_rle(segmentation: Any, height: int, width: int, path: Path, where: str) -> dict | None:
    """Convert a polygon list or (un)compressed RLE to a compressed RLE dict (``bytes`` counts)."""
    if segmentation is None:
        return None
    try:
        if isinstance(segmentation, list):  # polygons
            if not segmentation or not all(isinstance(p, list) and len(p) >= 6 and len(p) % 2 == 0
                                           for p in segmentation):
                raise ValueError("polygons must be lists of >= 3 x,y pairs")
            return mask_utils.merge(mask_utils.frPyObjects(segmentation, height, width))
        if isinstance(segmentation, dict) and "counts" in segmentation:
            size = segmentation.get("size")
            if list(size or []) != [height, width]:
                raise ValueError(f"RLE size {size} is not the video's [{height}, {width}]")
            counts = segmentation["counts"]
            if isinstance(counts, list):  # uncompressed
                if not all(isinstance(c, int) and not isinstance(c, bool) and c >= 0
                           for c in counts):
                    raise ValueError("uncompressed RLE counts must be non-negative integers")
                if sum(counts) != height * width:
                    raise ValueError(f"RLE run lengths sum to {sum(counts)} pixels, but a "
                                     f"{height}x{width} mask has {height * width}")
                return mask_utils.frPyObjects(segmentation, height, width)
            counts = counts.encode("ascii") if isinstance(counts, str) else counts
            if not isinstance(counts, bytes):
                raise ValueError(f"RLE counts must be a string or a list, not "
                                 f"{type(counts).__name__}")
            problem = check_rle(counts, height, width)
            if problem is not None:
                raise ValueError(problem)
            return {"size": [height, width], "counts": counts}
        raise ValueError("expected an RLE dict, a list of polygons or null")
    except (ValueError, TypeError, AttributeError, UnicodeEncodeError) as exc:
        raise DataFormatError(path, str(exc), field=where) from None


def rle_to_json(rle: dict | None, *, uncompressed: bool = False) -> dict | None:
    """Return a JSON-serialisable RLE.

    Compressed with ``str`` counts, or with ``uncompressed`` the list-of-run-lengths form the
    2019 annotation files use (column-major runs starting with background), which
    TrackEval's ground-truth loader requires.
    """
    if rle is None:
        return None
    if uncompressed:
        flat = mask_utils.decode(rle).ravel(order="F").astype(np.int8)
        edges = np.flatnonzero(np.diff(flat)) + 1
        bounds = np.concatenate([[0], edges, [flat.size]])
        runs = np.diff(bounds).tolist()
        if flat.size and flat[0] == 1:
            runs = [0] + runs
        return {"size": [int(v) for v in rle["size"]], "counts": runs}
    counts = rle["counts"]
    return {"size": [int(v) for v in rle["size"]],
            "counts": counts.decode("ascii") if isinstance(counts, bytes) else counts}


@dataclass(frozen=True)
class VisVideo:
    """One video: id, name (frame folder), frame files (relative), size and length."""

    id: int
    name: str
    file_names: tuple[str, ...]
    height: int
    width: int

    @property
    def length(self) -> int:
        """Number of annotated frames."""
        return len(self.file_names)


@dataclass(frozen=True)
class VisTrack:
    """One object track: ground truth, result or detection (one RLE or None per frame)."""

    video_id: int
    category_id: int
    segmentations: tuple[dict | None, ...]
    id: int = -1
    score: float = 1.0
    iscrowd: int = 0


@dataclass(frozen=True)
class VisData:
    """A parsed YouTube-VIS JSON: videos, categories and (where present) annotations."""

    path: Path
    videos: tuple[VisVideo, ...]
    categories: dict[int, str]
    tracks: tuple[VisTrack, ...] | None

    def video(self, name: str) -> VisVideo:
        """The video named ``name``."""
        for video in self.videos:
            if video.name == name:
                return video
        raise KeyError(f"no video {name!r} in {self.path}")

    def tracks_of(self, video_id: int) -> list[VisTrack]:
        """Annotations of one video (empty without annotations)."""
        return [t for t in self.tracks or () if t.video_id == video_id]


def _require(obj: Any, key: str, kind: type | tuple, path: Path, where: str) -> Any:
    if not isinstance(obj, dict) or key not in obj:
        raise DataFormatError(path, "missing", field=f"{where}.{key}")
    value = obj[key]
    if not isinstance(value, kind) or isinstance(value, bool):
        raise DataFormatError(path, f"has type {type(value).__name__}", field=f"{where}.{key}")
    return value


def _id(entry: dict, key: str, path: Path, where: str) -> int:
    """An id field: an int in ``0..MAX_ID`` (JSON allows ``2**70``; numpy and TrackEval not)."""
    return check_id(_require(entry, key, int, path, where), path, field=f"{where}.{key}")


def _load_json(path: Path, text: str | None) -> Any:
    if text is None and not path.exists():
        raise DataFormatError(path, "file not found")
    try:
        if text is None:
            return load_json_limited(path, MAX_SPLIT_JSON_BYTES, "YouTube-VIS file")
        return json.loads(text)
    except RecursionError:
        raise DataFormatError(path, "JSON nested too deep (more than about "
                                    f"{sys.getrecursionlimit():,} levels)") from None
    except json.JSONDecodeError as exc:
        raise DataFormatError(path, f"not valid JSON ({exc.msg})", line=exc.lineno) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFormatError(path, f"cannot read ({exc})") from None


def _segmentations(entry: dict, video: VisVideo, path: Path, where: str) -> tuple:
    segs = _require(entry, "segmentations", list, path, where)
    if len(segs) != video.length:
        raise DataFormatError(path, f"has {len(segs)} entries but video {video.id} has "
                              f"{video.length} frames", field=f"{where}.segmentations")
    return tuple(to_rle(s, video.height, video.width, path, f"{where}.segmentations[{i}]")
                 for i, s in enumerate(segs))


def parse_vis_json(path: str | os.PathLike, *, text: str | None = None) -> VisData:
    """Read a YouTube-VIS 2019 annotation file (``annotations`` may be absent or null).

    DataFormatError names the file and the JSON path of the first problem.
    """
    path = Path(path)
    data = _load_json(path, text)
    if not isinstance(data, dict):
        raise DataFormatError(path, "top level must be an object with videos and categories")
    videos = []
    for i, v in enumerate(_require(data, "videos", list, path, "")):
        where = f"videos[{i}]"
        names = _require(v, "file_names", list, path, where)
        if not names or not all(isinstance(n, str) and "/" in n for n in names):
            raise DataFormatError(path, "must be non-empty '<video>/<frame>' paths",
                                  field=f"{where}.file_names")
        video = VisVideo(_id(v, "id", path, where), names[0].split("/")[0],
                         tuple(names), _require(v, "height", int, path, where),
                         _require(v, "width", int, path, where))
        check_image_size(path, (video.width, video.height), field=f"{where}.width/height")
        length = v.get("length", video.length)
        if length != video.length:
            raise DataFormatError(path, f"length {length} but {video.length} file_names",
                                  field=f"{where}.length")
        videos.append(video)
    by_id = {v.id: v for v in videos}
    if len(by_id) != len(videos):
        raise DataFormatError(path, "duplicate video ids", field="videos")
    categories = {}
    for i, c in enumerate(_require(data, "categories", list, path, "")):
        categories[_require(c, "id", int, path, f"categories[{i}]")] = str(
            _require(c, "name", str, path, f"categories[{i}]"))
    tracks = None
    if data.get("annotations") is not None:
        tracks = []
        for i, a in enumerate(_require(data, "annotations", list, path, "")):
            where = f"annotations[{i}]"
            video_id = _require(a, "video_id", int, path, where)
            if video_id not in by_id:
                raise DataFormatError(path, f"unknown video {video_id}", field=f"{where}.video_id")
            category = _require(a, "category_id", int, path, where)
            if category not in categories:
                raise DataFormatError(path, f"unknown category {category}",
                                      field=f"{where}.category_id")
            tracks.append(VisTrack(video_id, category,
                                   _segmentations(a, by_id[video_id], path, where),
                                   id=_id(a, "id", path, where),
                                   iscrowd=int(a.get("iscrowd", 0))))
        tracks = tuple(tracks)
        per_video = Counter(t.video_id for t in tracks)  # TrackEval's matrices grow with it
        if per_video:
            video_id, count = per_video.most_common(1)[0]
            check_track_total(count, path, what=f"annotations (instances) of video {video_id}",
                              field="annotations")
    return VisData(path, tuple(videos), categories, tracks)


def parse_vis_results(source: str | os.PathLike | list, videos: dict[int, VisVideo], *,
                      path: Path | None = None,
                      categories: Mapping[int, str] | None = None) -> list[VisTrack]:
    """Read results-format entries (a file or a list) of the given videos; others are skipped.

    With ``categories``, an entry of another category is refused (the scorer would silently
    drop it). DataFormatError names the file and entry.
    """
    if isinstance(source, list):
        data, path = source, path or Path("<results>")
    else:
        path = Path(source)
        data = _load_json(path, None)
    if not isinstance(data, list):
        raise DataFormatError(path, "results must be a JSON list of predictions")
    out = []
    for i, entry in enumerate(data):
        where = f"[{i}]"
        video_id = _require(entry, "video_id", int, path, where)
        if video_id not in videos:
            continue
        score = _require(entry, "score", (int, float), path, where)
        if not np.isfinite(score):
            raise DataFormatError(path, "score is not finite", field=f"{where}.score")
        category = _require(entry, "category_id", int, path, where)
        if categories is not None and category not in categories:
            raise DataFormatError(
                path, f"unknown category {category}; the annotation file's categories are "
                      f"{sorted(categories)}", field=f"{where}.category_id")
        out.append(VisTrack(video_id, category,
                            _segmentations(entry, videos[video_id], path, where),
                            score=float(score)))
    return out


def format_results(tracks: list[VisTrack]) -> str:
    """Results JSON text: ``[{video_id, category_id, segmentations, score}]``."""
    return json.dumps([{"video_id": t.video_id, "category_id": t.category_id,
                        "segmentations": [rle_to_json(s) for s in t.segmentations],
                        "score": float(t.score)} for t in tracks])


def format_annotations(data: VisData, videos: list[VisVideo] | None = None) -> str:
    """Annotation JSON text (for TrackEval and the synthetic writer), with areas and boxes.

    Annotations carry ``height``/``width``/``length`` and uncompressed RLE as the 2019 train
    file does (TrackEval reads both).
    """
    videos = list(data.videos) if videos is None else videos
    keep = {v.id for v in videos}
    by_id = {v.id: v for v in videos}
    annotations = []
    for k, t in enumerate(data.tracks or ()):
        if t.video_id not in keep:
            continue
        v = by_id[t.video_id]
        areas = [float(mask_utils.area(s)) if s else None for s in t.segmentations]
        boxes = [[float(x) for x in mask_utils.toBbox(s)] if s else None for s in t.segmentations]
        annotations.append({
            "id": t.id if t.id >= 0 else k + 1, "video_id": t.video_id,
            "category_id": t.category_id, "iscrowd": t.iscrowd, "height": v.height,
            "width": v.width, "length": 1,
            "segmentations": [rle_to_json(s, uncompressed=True) for s in t.segmentations],
            "areas": areas, "bboxes": boxes,
        })
    payload = {
        "info": {"description": "unitrack-env"},
        "videos": [{"id": v.id, "width": v.width, "height": v.height, "length": v.length,
                    "file_names": list(v.file_names)} for v in videos],
        "categories": [{"id": c, "name": n, "supercategory": "object"}
                       for c, n in sorted(data.categories.items())],
        "annotations": annotations if data.tracks is not None else None,
    }
    return json.dumps(payload)


class YouTubeVISDataset:
    """A YouTube-VIS 2019 data set on disk (``detections``: ``"public"``, ``"gt"`` or a file)."""

    def __init__(self, root: str | os.PathLike, split: str = "train",
                 detections: str | os.PathLike = "public",
                 annotation_file: str | os.PathLike | None = None) -> None:
        self.root = Path(root)
        self.split = split
        self.annotation_path = Path(annotation_file) if annotation_file else \
            self.root / f"{split}.json"
        self.image_root = self.root / split / IMAGE_FOLDER
        self.data = parse_vis_json(self.annotation_path)
        for i, video in enumerate(self.data.videos):  # frames are read from inside the root
            for j, name in enumerate(video.file_names):
                path_inside(self.image_root, name, self.annotation_path,
                            field=f"videos[{i}].file_names[{j}]")
        self.detections = detections
        self.sequence_names = [v.name for v in self.data.videos]
        self._detections: dict[int, list[VisTrack]] | None = None

    @property
    def has_annotations(self) -> bool:
        """Whether the split's JSON has annotations."""
        return self.data.tracks is not None

    def video(self, name: str) -> VisVideo:
        """The video named ``name``."""
        return self.data.video(name)

    def frame_path(self, video: VisVideo, index: int) -> Path:
        """Image file of frame ``index`` (0-based position in ``file_names``)."""
        return self.image_root / video.file_names[index]

    def detection_path(self) -> Path:
        """The detection file (for ``detections`` not ``"gt"``)."""
        if str(self.detections) == "public":
            return self.root / "detections" / f"{self.split}.json"
        return Path(self.detections)

    def detections_of(self, video: VisVideo) -> list[VisTrack]:
        """Detection entries of a video (results format)."""
        if str(self.detections) == "gt":
            if not self.has_annotations:
                raise DataFormatError(self.annotation_path, "detections='gt' needs annotations, "
                                      "which this split does not have")
            return self.data.tracks_of(video.id)
        if self._detections is None:
            path = self.detection_path()
            if not path.is_file():
                raise DataFormatError(path, "detection file not found; YouTube-VIS ships no "
                                      "detections: pass detections=<results-format JSON> or 'gt'")
            by_id = {v.id: v for v in self.data.videos}
            grouped: dict[int, list[VisTrack]] = {}
            for t in parse_vis_results(path, by_id, categories=self.data.categories):
                grouped.setdefault(t.video_id, []).append(t)
            self._detections = grouped
        return self._detections.get(video.id, [])
