"""Reader of TAP-Vid-Kinetics: the official CSV of point tracks and the user's own clips.

The layout (google-deepmind/tapnet, ``data/README.md`` and ``tapvid/generate_tapvid.py``):
``tapvid_kinetics.csv`` (in ``tapvid_kinetics.zip``) has no header and one row per point
track: ``youtube_id, start_time_sec, end_time_sec`` and then ``x, y, occluded`` for each of
250 frames (10 s at 25 fps), ``x, y`` as fractions of the frame and ``occluded`` ``0``/``1``.
Rows of the same ``(youtube_id, start, end)`` are the tracks of one video. The videos are the
Kinetics-700-2020 validation clips, which the user downloads: MP4 files named
``{youtube_id}_{start:06}_{end:06}.mp4`` anywhere under a video root (commonly
``<root>/<action label>/<clip>.mp4``). Kinetics videos get taken down; the authors advise
scoring the videos still available (tapnet issue #121): ``missing_clips="skip"``.

Clips are decoded with OpenCV and brought to 25 fps as the reference's ``ffmpeg -vf fps=25``
does (output frame ``k`` shows the last source frame whose timestamp, in 1/25 s rounded to
nearest, is at most ``k``; exact for constant-frame-rate clips), cut at 250 frames; a
shorter clip keeps its annotations' first frames only, as ``generate_tapvid.py`` does, unless
they show a point visible more than 2 frames past its end (then it is not the clip that
was annotated: a partial download or another cut, refused naming it). Points
are moved by half a source pixel, ``(x W - 0.5) / W``, exactly as ``generate_tapvid.py``
writes them into its pickles, so that scores match those measured on the pickles.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.datasets.base import SequenceDataset
from unitrack_env.datasets.tapvid import PointVideo
from unitrack_env.errors import DataFormatError, UnknownSequenceError

#: Data set name (the ``benchmark=`` of the env).
KINETICS = "TAPVid-Kinetics"
#: The annotation file of the official zip.
CSV_NAME = "tapvid_kinetics.csv"
#: Annotated frames per row, and the frame rate they are annotated at.
FRAMES_PER_ROW = 250
FPS = 25
#: Fields of a row: the clip's key, then x, y, occluded per frame.
ROW_FIELDS = 3 + 3 * FRAMES_PER_ROW
#: A clip may run this many seconds past its segment before it is refused as untrimmed.
LENGTH_SLACK_S = 1.0
#: ``missing_clips=`` values.
MISSING_CLIPS: tuple[str, ...] = ("error", "skip")
#: Frames an annotated visible point may lie past the clip's end (rounding at the clip's
#: end in the 25 fps conversion); further out, the clip is not the one annotated.
END_SLACK_FRAMES = 2
#: Other containers a user's downloader may produce (named in the missing-clip error).
OTHER_SUFFIXES: tuple[str, ...] = (".mkv", ".webm", ".avi", ".mov")


@dataclass(frozen=True)
class KineticsClip:
    """The annotations of one clip: ``points`` ``(N, 250, 2)`` (CSV values), ``occluded``."""

    name: str
    segment_s: int
    points: np.ndarray
    occluded: np.ndarray
    first_line: int


def clip_name(youtube_id: str, start: int, end: int) -> str:
    """The official clip name, ``f"{youtube_id}_{start:06}_{end:06}"`` (without ``.mp4``)."""
    return f"{youtube_id}_{start:06}_{end:06}"


def _number(path: Path, line: int, field: str, text: str, kind: type) -> float:
    try:
        value = kind(text)
    except ValueError:
        what = "an integer" if kind is int else "a number"
        raise DataFormatError(path, f"{text!r} is not {what}", line=line,
                              field=field) from None
    if not math.isfinite(value):
        raise DataFormatError(path, f"{text!r} is not finite", line=line, field=field)
    return value


def _frame_values(path: Path, line: int, cells: list[str]) -> np.ndarray:
    """``(250, 3)`` x, y, occluded of a row's frame cells (a bad cell names its field)."""
    try:
        values = np.array(cells, dtype=np.float64).reshape(FRAMES_PER_ROW, 3)
        if set(cells[2::3]) <= {"0", "1"} and np.isfinite(values).all():
            return values
    except ValueError:
        pass
    values = np.empty((FRAMES_PER_ROW, 3))  # the slow way, to name the first bad cell
    for frame in range(FRAMES_PER_ROW):
        x, y, occ = cells[3 * frame: 3 * frame + 3]
        if occ.strip() not in ("0", "1"):
            raise DataFormatError(path, f"frame {frame}: {occ!r} is not 0 or 1", line=line,
                                  field=f"occluded[{frame}]")
        values[frame] = (_number(path, line, f"x[{frame}]", x, float),
                         _number(path, line, f"y[{frame}]", y, float), occ.strip() == "1")
    return values


def _parse_row(path: Path, line: int, row: list[str]) -> tuple[str, int, np.ndarray, np.ndarray]:
    """One row: its clip name, segment length (s), points ``(250, 2)`` and flags ``(250,)``."""
    if len(row) != ROW_FIELDS:
        raise DataFormatError(path, f"{len(row)} fields, expected {ROW_FIELDS} (youtube_id, "
                                    f"start_time_sec, end_time_sec, then x, y, occluded for "
                                    f"each of {FRAMES_PER_ROW} frames)", line=line)
    youtube_id = row[0].strip()
    if not youtube_id:
        raise DataFormatError(path, "is empty", line=line, field="youtube_id")
    start = int(_number(path, line, "start_time_sec", row[1], int))
    end = int(_number(path, line, "end_time_sec", row[2], int))
    if not 0 <= start < end:
        raise DataFormatError(path, f"segment {start}..{end} s is not 0 <= start < end",
                              line=line, field="end_time_sec")
    values = _frame_values(path, line, row[3:])
    occluded = values[:, 2] > 0
    outside = ~occluded & ((values[:, :2] < 0) | (values[:, :2] > 1)).any(axis=1)
    if outside.any():
        frame = int(np.flatnonzero(outside)[0])
        axis = "x" if not 0 <= values[frame, 0] <= 1 else "y"
        raise DataFormatError(path, f"frame {frame}: visible point at "
                                    f"{values[frame, :2].tolist()}, outside 0..1 (x, y are "
                                    "fractions of the frame)", line=line,
                              field=f"{axis}[{frame}]")
    return clip_name(youtube_id, start, end), end - start, values[:, :2], occluded


def read_kinetics_csv(path: str | Path) -> dict[str, KineticsClip]:
    """The clips of ``tapvid_kinetics.csv`` in file order; a bad row names its line and field."""
    path = Path(path)
    rows: dict[str, list] = {}
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            for line, row in enumerate(csv.reader(handle), start=1):
                if not row or not "".join(row).strip():
                    continue
                name, segment, points, occluded = _parse_row(path, line, row)
                rows.setdefault(name, [segment, [], [], line])
                rows[name][1].append(points)
                rows[name][2].append(occluded)
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise DataFormatError(path, f"cannot be read as CSV ({err})") from None
    if not rows:
        raise DataFormatError(path, "holds no point tracks")
    return {name: KineticsClip(name, segment, np.stack(points).astype(np.float64),
                               np.stack(flags), line)
            for name, (segment, points, flags, line) in rows.items()}


def index_clips(video_root: Path) -> dict[str, list[Path]]:
    """Every video file under ``video_root`` by its stem (any depth)."""
    found: dict[str, list[Path]] = {}
    suffixes = (".mp4", *OTHER_SUFFIXES)
    for path in sorted(video_root.rglob("*")):
        if path.suffix.lower() in suffixes and path.is_file():
            found.setdefault(path.stem, []).append(path)
    return found


def _slots(times_s: np.ndarray | float, fps: int = FPS) -> np.ndarray:
    """Times in output frames, rounded to nearest (halves up), as ffmpeg's fps filter does."""
    return np.floor(np.asarray(times_s, np.float64) * fps + 0.5 + 1e-6).astype(np.int64)


def fps_slots(timestamps_s: np.ndarray, end_s: float, fps: int = FPS) -> np.ndarray:
    """Source frame shown at each output frame of ``ffmpeg -vf fps=<fps>`` (round to nearest).

    ``timestamps_s``: each source frame's time from the first; ``end_s``: the end of the
    last frame. There are ``round(end_s * fps)`` output frames (at least one); output frame
    ``k`` shows the last source frame whose time, in output frames rounded to nearest, is
    at most ``k``.

    >>> fps_slots(np.arange(6) / 30, 6 / 30).tolist()  # 30 fps -> 25 fps drops one frame
    [0, 1, 2, 4, 5]
    """
    count = max(int(_slots(end_s, fps)), 1)
    picks = np.searchsorted(_slots(timestamps_s, fps), np.arange(count), side="right") - 1
    return np.maximum(picks, 0)


def _resized(image: np.ndarray, size: tuple[int, int] | None) -> np.ndarray:
    """``image`` (BGR) as RGB at ``size`` ``(width, height)`` (None: as decoded)."""
    rgb = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    if size is None or rgb.shape[1::-1] == tuple(size):
        return rgb
    shrink = rgb.shape[1] > size[0]
    return cv2.resize(rgb, tuple(size), interpolation=cv2.INTER_AREA if shrink
                      else cv2.INTER_LINEAR)


@dataclass
class _Decoded:
    """What :func:`_read_all` kept of a clip.

    Frames that 25 fps output can show, their times (s from the first frame), the end of
    the last frame read (s) and the source size (w, h).
    """

    images: list[np.ndarray]
    times: list[float]
    end_s: float = 0.0
    source: tuple[int, int] = (0, 0)


def _read_all(capture: cv2.VideoCapture, size: tuple[int, int] | None,
              limit_s: float) -> _Decoded:
    """Read the clip, keeping only frames that 25 fps output can show (within 250 frames).

    A frame whose 25 fps slot the next frame takes too is never shown (ffmpeg shows the
    last one): it is replaced, so memory holds at most 250 frames. Stops past ``limit_s``.
    """
    fps = capture.get(cv2.CAP_PROP_FPS) or FPS
    kept, first, last = _Decoded([], []), None, None
    while True:
        ok, image = capture.read()
        if not ok:
            break
        stamp = capture.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
        if first is None:
            first, kept.source = stamp, (int(image.shape[1]), int(image.shape[0]))
        elif stamp <= last:  # a backend without timestamps: the stated frame rate
            stamp = last + 1.0 / fps
        last = stamp
        slot = int(_slots(stamp - first))
        if kept.times and int(_slots(kept.times[-1])) == slot:
            kept.images[-1], kept.times[-1] = _resized(image, size), stamp - first
        elif slot < FRAMES_PER_ROW:
            kept.images.append(_resized(image, size))
            kept.times.append(stamp - first)
        if stamp - first > limit_s:
            break
    if last is not None:
        kept.end_s = last - first + 1.0 / fps
    return kept


def decode_clip(path: Path, size: tuple[int, int] | None,
                segment_s: int) -> tuple[np.ndarray, tuple[int, int]]:
    """The clip at 25 fps (at most 250 frames, RGB, at ``size``) and its source (w, h).

    Refused, naming the file: a clip OpenCV cannot open or decode, and one longer than its
    segment by more than :data:`LENGTH_SLACK_S` (an untrimmed video: the annotations would
    not line up with its frames).
    """
    capture = cv2.VideoCapture(str(path))
    try:
        if not capture.isOpened():
            raise DataFormatError(path, "OpenCV cannot open this clip (is it a video file? "
                                        f"this cv2 {cv2.__version__} reads H.264, HEVC, VP9, "
                                        "AV1 and MPEG-4 Part 2 through its FFmpeg backend)")
        kept = _read_all(capture, size, segment_s + LENGTH_SLACK_S)
    finally:
        capture.release()
    if not kept.images:
        raise DataFormatError(path, "OpenCV decodes no frame from this clip (unsupported "
                                    "codec or a broken download)")
    if kept.end_s > segment_s + LENGTH_SLACK_S:
        raise DataFormatError(path, f"the clip runs {kept.end_s:.1f} s or more, its segment "
                                    f"{segment_s} s: an untrimmed video? TAP-Vid-Kinetics "
                                    "annotates the trimmed Kinetics clip (named _start_end)")
    picks = fps_slots(np.asarray(kept.times), kept.end_s)[:FRAMES_PER_ROW]
    return np.stack([kept.images[i] for i in picks]), kept.source


class KineticsDataset(SequenceDataset[PointVideo]):
    """The annotated clips of a TAP-Vid-Kinetics folder, read with the user's own clips.

    ``root``: the folder holding ``tapvid_kinetics.csv`` (or that file); ``video_root``: the
    folder searched, at any depth, for the clips (default: the CSV's folder); ``size``:
    ``(width, height)`` the frames are resized to while decoding (None: as stored);
    ``missing_clips``: ``"error"`` (a clip not found is refused, naming the path expected)
    or ``"skip"`` (play the clips found; :attr:`missing` names the others). The CSV and the
    clips' presence are checked here; a clip is decoded and checked when loaded, and only
    the last loaded clip is kept in memory.
    """

    def __init__(self, root: str | Path, video_root: str | Path | None = None,
                 size: tuple[int, int] | None = None, missing_clips: str = "error") -> None:
        if missing_clips not in MISSING_CLIPS:
            raise ValueError(f"missing_clips must be one of {MISSING_CLIPS}, got "
                             f"{missing_clips!r}")
        self.root = Path(root)
        self.benchmark = KINETICS
        self.csv_path = self.root if self.root.is_file() else self.root / CSV_NAME
        if not self.csv_path.is_file():
            raise DataFormatError(self.csv_path, "not found: the TAP-Vid-Kinetics annotations "
                                                 "(tapvid_kinetics.zip of google-deepmind/tapnet)")
        self.video_root = Path(video_root) if video_root is not None else self.csv_path.parent
        if not self.video_root.is_dir():
            raise DataFormatError(self.video_root, "is not a folder (video_root: where the "
                                                   "Kinetics clips are)")
        self.size = None if size is None else (int(size[0]), int(size[1]))
        self.clips = read_kinetics_csv(self.csv_path)
        self._paths, self.missing = self._find_clips(missing_clips)
        self.sequence_names: list[str] = [name for name in self.clips if name in self._paths]
        if not self.sequence_names:
            raise DataFormatError(self.video_root, f"holds none of the {len(self.clips)} clips "
                                                   f"{self.csv_path.name} annotates, e.g. "
                                                   f"{next(iter(self.clips))}.mp4")
        self._last: tuple[str, PointVideo] | None = None

    def _find_clips(self, missing_clips: str) -> tuple[dict[str, Path], list[str]]:
        """Each annotated clip's file, and the names of those not found."""
        index = index_clips(self.video_root)
        paths, missing = {}, []
        for name in self.clips:
            mp4 = [p for p in index.get(name, []) if p.suffix.lower() == ".mp4"]
            if len(mp4) > 1:
                raise DataFormatError(mp4[1], f"clip '{name}' is also at {mp4[0]}; keep one")
            if mp4:
                paths[name] = mp4[0]
                continue
            if missing_clips == "error":
                other = index.get(name, [])
                hint = (f" ({other[0].name} is there: the layout names MP4 clips)" if other
                        else "")
                raise DataFormatError(
                    self.video_root / f"{name}.mp4",
                    f"not found{hint}: the clip that {self.csv_path.name} line "
                    f"{self.clips[name].first_line} annotates (any sub-folder of "
                    f"{self.video_root} is searched). Kinetics videos get taken down: "
                    "missing_clips='skip' plays the clips that are there")
            missing.append(name)
        return paths, missing

    def file_of(self, name: str) -> Path:
        """The clip of video ``name``."""
        return self._paths[name]

    def inputs_of(self, name: str) -> list[Path]:
        """The files video ``name`` is read from: the CSV and the clip."""
        return [self.csv_path, self._paths[name]]

    def load(self, name: str) -> PointVideo:
        """Video ``name``: its clip decoded at 25 fps and its tracks (checked)."""
        if name not in self._paths:
            raise UnknownSequenceError(
                f"no clip '{name}' in {self.video_root}; {len(self.sequence_names)} "
                f"available, e.g. {self.sequence_names[0]}")
        if self._last is None or self._last[0] != name:
            self._last = None  # release the previous clip before decoding the next
            self._last = (name, self._read(name))
        return self._last[1]

    def _read(self, name: str) -> PointVideo:
        clip, path = self.clips[name], self._paths[name]
        frames, (width, height) = decode_clip(path, self.size, clip.segment_s)
        count = len(frames)
        late = np.argwhere(~clip.occluded[:, count + END_SLACK_FRAMES:])
        if len(late):
            track, frame = int(late[0, 0]), int(late[0, 1]) + count + END_SLACK_FRAMES
            raise DataFormatError(path, f"decodes to {count} frames at {FPS} fps, but "
                                        f"{self.csv_path.name} shows track {track} visible "
                                        f"at frame {frame}: a partial download or another "
                                        "cut of the video?")
        # generate_tapvid.py: (x W - 0.5) / W, in the clip's own pixels
        size = np.array([width, height], np.float64)
        points = ((clip.points[:, :count] * size - 0.5) / size).astype(np.float32)
        occluded = clip.occluded[:, :count].copy()
        for array in (frames, points, occluded):
            array.setflags(write=False)
        return PointVideo(name, frames, points, occluded, path)
