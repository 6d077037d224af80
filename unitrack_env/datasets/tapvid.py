"""Reader of the TAP-Vid point tracking pickles (DAVIS, RGB-Stacking, RoboTAP).

The official files (google-deepmind/tapnet's README) are pickles of numpy arrays:
``tapvid_davis.pkl`` and RoboTAP's ``robotap_split*.pkl`` a dict ``{video name: video}``,
``tapvid_rgb_stacking.pkl`` a list of videos, where a video is a dict of ``video`` uint8
``[T, H, W, 3]``, ``points`` float32 ``[N, T, 2]`` (x, y in 0..1 of the frame) and
``occluded`` bool ``[N, T]``. They are never unpickled blindly: :class:`RestrictedUnpickler`
admits only numpy's array, dtype and scalar reconstruction (Python docs, "Restricting
Globals") and refuses every other global naming the file and the global, before any of the
file's code could run. Shapes, dtypes and ranges are checked per video when it is loaded.
"""

from __future__ import annotations

import io
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from unitrack_env.datasets.base import SequenceDataset
from unitrack_env.errors import DataFormatError, UnknownSequenceError

#: The globals a TAP-Vid pickle may name: numpy's array, dtype and scalar reconstruction
#: under NumPy 1.x (``numpy.core``) and 2.x (``numpy._core``) module names. Containers
#: (dict, list, tuple) and strings are pickle opcodes, not globals.
ALLOWED_GLOBALS: frozenset[tuple[str, str]] = frozenset(
    (module, name)
    for core in ("numpy.core", "numpy._core")
    for module, name in ((f"{core}.multiarray", "_reconstruct"),
                         (f"{core}.multiarray", "scalar"),
                         (f"{core}.numeric", "_frombuffer"))
) | {("numpy", "ndarray"), ("numpy", "dtype")}

#: The pickle(s) of each data set in its folder (RoboTAP ships five splits).
PICKLE_PATTERNS: dict[str, str] = {
    "TAPVid-DAVIS": "tapvid_davis.pkl",
    "TAPVid-RGBStacking": "tapvid_rgb_stacking.pkl",
    "RoboTAP": "robotap_split*.pkl",
}

#: Slack on the 0..1 range of visible points (float32 rounding of a border point).
RANGE_SLACK = 1e-3


class RefusedGlobal(DataFormatError):
    """A pickle asked for a global outside :data:`ALLOWED_GLOBALS`."""


class RestrictedUnpickler(pickle.Unpickler):
    """An unpickler that resolves only :data:`ALLOWED_GLOBALS` (``path`` names the file)."""

    def __init__(self, file: Any, path: Path) -> None:
        super().__init__(file)
        self.path = path

    def find_class(self, module: str, name: str) -> Any:
        """Resolve an admitted global; refuse any other, naming it."""
        if (module, name) not in ALLOWED_GLOBALS:
            raise RefusedGlobal(self.path, f"the pickle asks for the global {module}.{name}, "
                                "which a TAP-Vid file never needs (only numpy arrays, dtypes "
                                "and scalars are admitted); it was not loaded")
        return super().find_class(module, name)


def restricted_load(path: str | Path) -> Any:
    """Unpickle ``path`` with :class:`RestrictedUnpickler`; any failure names the file."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as err:
        raise DataFormatError(path, f"cannot read ({err.strerror or err})") from None
    try:
        return RestrictedUnpickler(io.BytesIO(data), path).load()
    except RefusedGlobal:
        raise
    except Exception as err:  # noqa: BLE001 - a corrupt pickle raises many kinds of errors
        raise DataFormatError(path, f"is not a readable pickle ({type(err).__name__}: "
                                    f"{err})") from None


@dataclass(frozen=True)
class PointVideo:
    """One TAP-Vid video, as the pickle holds it (checked).

    ``frames`` uint8 ``(T, H, W, 3)``, ``points`` ``(N, T, 2)`` x, y in 0..1, ``occluded``
    bool ``(N, T)``; ``source`` names the file it came from.
    """

    name: str
    frames: np.ndarray
    points: np.ndarray
    occluded: np.ndarray
    source: Path

    @property
    def num_frames(self) -> int:
        """Number of frames ``T``."""
        return int(self.frames.shape[0])

    @property
    def image_size(self) -> tuple[int, int]:
        """``(width, height)`` of the stored frames."""
        return int(self.frames.shape[2]), int(self.frames.shape[1])


def check_video(path: Path, name: str, entry: Any) -> PointVideo:
    """Validate one pickle entry (shapes, dtypes, ranges) into a :class:`PointVideo`."""
    where = f"video '{name}'"
    if not isinstance(entry, dict):
        raise DataFormatError(path, f"{where} is a {type(entry).__name__}, expected a dict "
                                    "with 'video', 'points' and 'occluded'")
    missing = [key for key in ("video", "points", "occluded") if key not in entry]
    if missing:
        raise DataFormatError(path, f"{where} has no {missing}", field=missing[0])
    frames, points, occluded = (entry[key] for key in ("video", "points", "occluded"))
    for key, value in (("video", frames), ("points", points), ("occluded", occluded)):
        if not isinstance(value, np.ndarray):
            raise DataFormatError(path, f"{where}: '{key}' is a {type(value).__name__}, "
                                        "expected a numpy array", field=key)
    if frames.dtype != np.uint8 or frames.ndim != 4 or frames.shape[3] != 3 \
            or min(frames.shape) < 1:
        raise DataFormatError(path, f"{where}: 'video' is {frames.dtype} {frames.shape}, "
                                    "expected uint8 [T, H, W, 3]", field="video")
    frame_count = frames.shape[0]
    if points.ndim != 3 or points.shape[1:] != (frame_count, 2) \
            or not np.issubdtype(points.dtype, np.floating):
        raise DataFormatError(path, f"{where}: 'points' is {points.dtype} {points.shape}, "
                                    f"expected float [N, {frame_count}, 2]", field="points")
    if occluded.dtype != np.bool_ or occluded.shape != points.shape[:2]:
        raise DataFormatError(path, f"{where}: 'occluded' is {occluded.dtype} "
                                    f"{occluded.shape}, expected bool {points.shape[:2]}",
                              field="occluded")
    visible = points[~occluded]
    bad = ~np.isfinite(visible).all(axis=1) | (visible < -RANGE_SLACK).any(axis=1) \
        | (visible > 1 + RANGE_SLACK).any(axis=1)
    if bad.any():
        track, frame = (int(v) for v in np.argwhere(~occluded)[np.flatnonzero(bad)[0]])
        raise DataFormatError(path, f"{where}: visible point {track} at frame {frame} is "
                                    f"{points[track, frame].tolist()}, outside 0..1 (points "
                                    "are x, y as fractions of the frame)", field="points")
    # Occluded entries are never scored; a NaN there would only poison arithmetic.
    clean = np.where(occluded[..., None], np.nan_to_num(points), points).astype(np.float32)
    frames.setflags(write=False)
    clean.setflags(write=False)
    occluded = occluded.copy()
    occluded.setflags(write=False)
    return PointVideo(name, frames, clean, occluded, path)


def read_point_pickle(path: str | Path) -> dict[str, tuple[Path, Any]]:
    """``{video name: raw entry}`` of one pickle (a dict by name, or a list: names "0", "1")."""
    path = Path(path)
    data = restricted_load(path)
    if isinstance(data, dict):
        bad = [key for key in data if not isinstance(key, str)]
        if bad:
            raise DataFormatError(path, f"video names must be strings, got {bad[0]!r}")
        return {name: (path, entry) for name, entry in data.items()}
    if isinstance(data, list):
        return {str(index): (path, entry) for index, entry in enumerate(data)}
    raise DataFormatError(path, f"holds a {type(data).__name__}; a TAP-Vid pickle is a dict "
                                "{video name: video} or a list of videos")


class TAPVidDataset(SequenceDataset[PointVideo]):
    """The videos of a TAP-Vid folder (``benchmark``: a key of :data:`PICKLE_PATTERNS`).

    A ``root`` that is itself a ``.pkl`` file is read as the data set's one pickle. Videos
    are validated when loaded (:func:`check_video`).
    """

    def __init__(self, root: str | Path, benchmark: str = "TAPVid-DAVIS") -> None:
        if benchmark not in PICKLE_PATTERNS:
            raise ValueError(f"unknown TAP-Vid data set {benchmark!r}; valid: "
                             f"{', '.join(PICKLE_PATTERNS)}")
        self.root = Path(root)
        self.benchmark = benchmark
        files = [self.root] if self.root.is_file() else \
            sorted(self.root.glob(PICKLE_PATTERNS[benchmark]))
        if not files:
            raise DataFormatError(self.root, f"no {PICKLE_PATTERNS[benchmark]} in this folder "
                                             f"(the official {benchmark} pickle)")
        self.files = files
        self._entries: dict[str, tuple[Path, Any]] = {}
        for path in files:
            for name, entry in read_point_pickle(path).items():
                if name in self._entries:
                    raise DataFormatError(path, f"video '{name}' is also in "
                                                f"{self._entries[name][0]}")
                self._entries[name] = entry
        if not self._entries:
            raise DataFormatError(files[0], "holds no videos")
        self.sequence_names: list[str] = list(self._entries)
        self._checked: dict[str, PointVideo] = {}

    def file_of(self, name: str) -> Path:
        """The pickle that holds video ``name``."""
        return self._entries[name][0]

    def inputs_of(self, name: str) -> list[Path]:
        """The files video ``name`` is read from: its pickle."""
        return [self.file_of(name)]

    def load(self, name: str) -> PointVideo:
        """Video ``name``, validated (once)."""
        if name not in self._entries:
            raise UnknownSequenceError(
                f"no video '{name}' in {self.root}; {len(self.sequence_names)} available, "
                f"e.g. {self.sequence_names[0]}")
        if name not in self._checked:
            path, entry = self._entries[name]
            self._checked[name] = check_video(path, name, entry)
        return self._checked[name]
