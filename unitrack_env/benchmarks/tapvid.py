"""The TAP-Vid point tracking benchmark: AJ, ``<δ^x_avg`` and OA (Doersch et al. 2022).

Results of one video are a ``<folder>/<video>.npz`` that any outside script can rescore:
``query_points`` ``(Q, 3)`` (t, y, x), ``tracks`` ``(Q, T, 2)`` (x, y) and ``occluded``
``(Q, T)`` bool, in pixels of the evaluation raster and in the reference's query order
(:mod:`unitrack_env.metrics.point_queries`).
"""

from __future__ import annotations

import io
import os
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from unitrack_env.benchmarks.base import Benchmark, data_root, one_of, rounded_digest
from unitrack_env.benchmarks.views import Head, ReportView, ScorecardColumn
from unitrack_env.datasets.tapvid import PointVideo, TAPVidDataset
from unitrack_env.datasets.tapvid_kinetics import KINETICS, KineticsDataset
from unitrack_env.errors import DataFormatError
from unitrack_env.io import atomic_write_bytes
from unitrack_env.metrics.events_mot import EventRows
from unitrack_env.metrics.point_queries import (
    EVAL_SIZE,
    PointQueries,
    check_query_mode,
    episode_schedule,
    sample_queries,
    to_raster,
)
from unitrack_env.metrics.points import (
    COLUMNS,
    evaluated_pairs,
    event_rows,
    frame_values,
    mean_over_videos,
    metrics_from_counts,
    pair_counts,
    video_metrics,
)
from unitrack_env.metrics.report import COMBINED, ScoreReport

#: The arrays of a result file, in the order they are written.
RESULT_KEYS: tuple[str, ...] = ("query_points", "tracks", "occluded")
#: ``resolution=`` values: the published 256 x 256 raster, or each video's own size.
RESOLUTIONS: tuple[str, ...] = ("256", "full")
#: Folder of each data set under ``$UNITRACK_DATA``.
FOLDERS: dict[str, str] = {"TAPVid-DAVIS": "TAPVid", "TAPVid-RGBStacking": "TAPVid",
                           "RoboTAP": "RoboTAP", KINETICS: "TAPVid-Kinetics"}
#: Query points of a result file may differ from the ground truth's by this much (pixels).
QUERY_TOLERANCE = 1e-3
#: A fixed zip timestamp, so equal results are equal bytes.
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """An uncompressed ``.npz`` of ``arrays`` (readable by ``np.load``), byte-stable."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_STORED) as archive:
        for key, array in arrays.items():
            member = io.BytesIO()
            np.lib.format.write_array(member, np.ascontiguousarray(array), allow_pickle=False)
            archive.writestr(zipfile.ZipInfo(f"{key}.npy", _ZIP_TIME), member.getvalue())
    return buffer.getvalue()


def read_results(path: Path, num_frames: int | None = None) -> dict[str, np.ndarray]:
    """Read and check a result ``.npz`` (never unpickles); errors name the file and array."""
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {key: archive[key] for key in archive.files}
    except (OSError, ValueError, zipfile.BadZipFile) as err:
        raise DataFormatError(path, f"is not a readable .npz ({err})") from None
    missing = [key for key in RESULT_KEYS if key not in arrays]
    if missing:
        raise DataFormatError(path, f"has no array {missing[0]!r} (a result file holds "
                                    f"{', '.join(RESULT_KEYS)})", field=missing[0])
    queries, tracks, occluded = (arrays[key] for key in RESULT_KEYS)
    count = len(queries)
    frames = tracks.shape[1] if tracks.ndim == 3 else num_frames
    expected = {"query_points": (count, 3), "tracks": (count, frames, 2),
                "occluded": (count, frames)}
    if num_frames is not None and frames != num_frames:
        raise DataFormatError(path, f"tracks cover {frames} frames, the video has {num_frames}",
                              field="tracks")
    for key in RESULT_KEYS:
        if arrays[key].shape != expected[key]:
            raise DataFormatError(path, f"{key} has shape {arrays[key].shape}, expected "
                                        f"{expected[key]}", field=key)
    if occluded.dtype != np.bool_:
        raise DataFormatError(path, f"occluded is {occluded.dtype}, expected bool",
                              field="occluded")
    for key in ("query_points", "tracks"):
        if not np.issubdtype(arrays[key].dtype, np.number) or \
                not np.isfinite(arrays[key]).all():
            raise DataFormatError(path, f"{key} must hold finite numbers", field=key)
    return {key: arrays[key] for key in RESULT_KEYS}


class TAPVidBenchmark(Benchmark):
    """TAP-Vid metrics of point tracks (per video, then the mean over videos).

    ``results`` of one video: a dict of :data:`RESULT_KEYS` arrays (see the module).
    """

    task = "points"
    columns = COLUMNS

    #: The report's curve: each frame's ``<δ^x_avg`` over its points visible in the ground
    #: truth (the ``pck`` column of its ``"frame"`` event).
    report_view = ReportView(value=("pck", "<δx visible"), value_type="frame")
    #: AJ, <δ^x_avg and OA are ratios of sums over a video's (query, frame) pairs, then means
    #: over videos: ``compare`` recomputes them from per-frame sums (:meth:`frame_counts`).
    intervals = "counts"
    #: Opt-in (``--tasks points``): the default scorecard stays the paper's Table 2 tasks.
    scorecard = ScorecardColumn(
        "Points", ("UniTrack/TAPVid-DAVIS-v0",),
        (Head("unitrack-points", "UniTrack", COLUMNS),),
        Head("static-points", "static-points", COLUMNS, appearance=False),
        ("UniTrack", "AJ"), order=8, input_size=(1, 256, 256), opt_in=True)

    def __init__(self, dataset: TAPVidDataset | KineticsDataset, query_mode: str = "first",
                 resolution: str = "256", *, synthetic: bool = False) -> None:
        super().__init__(dataset, synthetic=synthetic)
        self.query_mode = check_query_mode(query_mode)
        self.resolution = one_of("resolution", str(resolution), RESOLUTIONS)

    @classmethod
    def build(cls, root: str | os.PathLike | None = None, benchmark: str = "TAPVid-DAVIS",
              query_mode: str = "first", resolution: str = "256",
              video_root: str | os.PathLike | None = None,
              missing_clips: str = "error") -> TAPVidBenchmark:
        """The benchmark of ``TAPVidEnv(root=, benchmark=, query_mode=, resolution=, ...)``.

        ``video_root`` and ``missing_clips`` concern TAP-Vid-Kinetics only (its clips are
        decoded straight to the evaluation raster).
        """
        one_of("TAP-Vid data set", benchmark, FOLDERS)
        resolution = one_of("resolution", str(resolution), RESOLUTIONS)
        path, synthetic = data_root(root, FOLDERS[benchmark], benchmark, kind="tapvid")
        if benchmark == KINETICS:
            size = EVAL_SIZE if resolution == "256" else None
            dataset: TAPVidDataset | KineticsDataset = KineticsDataset(
                path, video_root, size, missing_clips)
        else:
            if video_root is not None or missing_clips != "error":
                raise ValueError(f"video_root= and missing_clips= are TAP-Vid-Kinetics "
                                 f"options; {benchmark} reads its videos from its pickle")
            dataset = TAPVidDataset(path, benchmark)
        return cls(dataset, query_mode, resolution, synthetic=synthetic)

    @property
    def name(self) -> str:
        """``"<data set> (<query mode>, <raster>)"``, e.g. ``"TAPVid-DAVIS (first, 256)"``."""
        return f"{self.dataset.benchmark} ({self.query_mode}, {self.resolution})"

    def load(self, name: str) -> PointVideo:
        """Video ``name`` (validated once)."""
        return self.dataset.load(name)

    def raster(self, name: str) -> tuple[int, int]:
        """``(width, height)`` of the evaluation raster of video ``name``."""
        return EVAL_SIZE if self.resolution == "256" else self.load(name).image_size

    def frame_array(self, sequence: str, frame: int) -> np.ndarray | None:
        """1-based ``frame`` of the pickle's video, resized to the evaluation raster."""
        video = self.load(sequence)
        if not 1 <= frame <= video.num_frames:
            return None
        image = video.frames[frame - 1]
        size = self.raster(sequence)
        if size == video.image_size:
            return image
        return np.asarray(Image.fromarray(image).resize(size, Image.BILINEAR))

    def queries(self, name: str) -> PointQueries:
        """The queries of video ``name`` with their ground truth, in raster pixels."""
        def sample(video_name: str) -> PointQueries:
            video = self.load(video_name)
            return sample_queries(to_raster(video.points, self.raster(video_name)),
                                  video.occluded, self.query_mode)

        return self._load_once(name, sample)

    def sequence_length(self, name: str) -> int:
        """Steps of the episode of ``name`` (a strided episode adds its reversed pass)."""
        return len(episode_schedule(self.load(name).num_frames,
                                    self.queries(name).query_frames, self.query_mode))

    def has_ground_truth(self, name: str) -> bool:
        """Every TAP-Vid video is annotated."""
        return name in self.dataset.sequence_names

    def write(self, folder: str | os.PathLike, sequence: str, results: dict[str, Any]) -> None:
        """Write ``<folder>/<sequence>.npz``."""
        arrays = {"query_points": np.asarray(results["query_points"], np.float32),
                  "tracks": np.asarray(results["tracks"], np.float32),
                  "occluded": np.asarray(results["occluded"], bool)}
        atomic_write_bytes(Path(folder) / f"{sequence}.npz", npz_bytes(arrays))

    def read(self, folder: str | os.PathLike, sequence: str) -> dict[str, np.ndarray]:
        """Read ``<folder>/<sequence>.npz`` back (checked)."""
        return read_results(Path(folder) / f"{sequence}.npz")

    def digest(self, results: dict[str, Any]) -> str:
        """SHA-256 of the tracks (rounded to 1e-3 px) and the occlusion flags."""
        tracks = np.asarray(results["tracks"], np.float64)
        flags = np.asarray(results["occluded"], np.float64)[..., None]
        return rounded_digest(np.concatenate([tracks, flags], axis=-1))

    def score_sequence(self, sequence: str, results: dict[str, Any],
                       path: Path | None = None) -> dict[str, float]:
        """The metrics of one video's results (their queries must be the ground truth's)."""
        truth = self._checked_queries(sequence, results, path)
        return video_metrics(truth.query_points, truth.tracks, truth.occluded,
                             np.asarray(results["tracks"]), np.asarray(results["occluded"]),
                             self.query_mode)

    def _checked_queries(self, sequence: str, results: dict[str, Any],
                         path: Path | None) -> PointQueries:
        """The ground-truth queries of ``sequence``, if the results answer exactly those."""
        truth = self.queries(sequence)
        where = path or Path(f"<{sequence} results>")
        given = np.asarray(results["query_points"], np.float64)
        if given.shape != truth.query_points.shape or \
                np.abs(given - truth.query_points).max(initial=0) > QUERY_TOLERANCE:
            raise DataFormatError(where, f"query_points are not the {len(truth)} queries of "
                                         f"'{sequence}' in {self.name} (sampled as the "
                                         "reference does; see docs/envs/tapvid.md)",
                                  field="query_points")
        return truth

    def sequence_events(self, folder: str | os.PathLike, sequence: str) -> EventRows:
        """Per frame (1-based) a ``"frame"`` event, per evaluated (query, frame) pair one more.

        ``"frame"``: ``pck`` = the frame's ``<δ^x_avg`` over its points visible in the ground
        truth (NaN if none). A pair is a ``"point"`` event when its predicted occlusion flag
        is right, an ``"occlusion_error"`` when wrong; ``object`` = the query, ``x, y`` the
        true and ``tx, ty`` the predicted position, ``distance`` their distance in raster
        pixels (NaN where the point is occluded in the ground truth).
        """
        path = Path(folder) / f"{sequence}.npz"
        results = read_results(path, self.load(sequence).num_frames)
        truth = self._checked_queries(sequence, results, path)
        evaluated = evaluated_pairs(truth.query_frames, truth.occluded.shape[1],
                                    self.query_mode)
        arrays = (results["tracks"], results["occluded"], truth.tracks, truth.occluded,
                  evaluated)
        per_frame = frame_values(*arrays)["delta_x_avg"]
        rows = EventRows(sequence)
        for t, value in enumerate(per_frame, start=1):
            rows.add(t, "frame", pck=float(value))
        for pair in event_rows(*arrays):
            t, q = int(pair["frame"]), int(pair["query"])
            x, y = map(float, truth.tracks[q, t])
            tx, ty = map(float, results["tracks"][q, t])
            error = pair["error_px"]
            rows.add(t + 1, "point" if pair["occlusion_correct"] else "occlusion_error",
                     object=q, x=x, y=y, tx=tx, ty=ty,
                     distance=float("nan") if error is None else float(error))
        return rows

    def frame_counts(self, folder: str | os.PathLike, sequence: str) -> dict[str, np.ndarray]:
        """Per frame the counts of one video's evaluated pairs (:func:`pair_counts`)."""
        path = Path(folder) / f"{sequence}.npz"
        results = read_results(path, self.load(sequence).num_frames)
        truth = self._checked_queries(sequence, results, path)
        evaluated = evaluated_pairs(truth.query_frames, truth.occluded.shape[1],
                                    self.query_mode)
        return pair_counts(results["tracks"], results["occluded"], truth.tracks,
                           truth.occluded, evaluated, axis=0)

    def metrics_of_counts(self, counts: Mapping[str, float]) -> dict[str, float]:
        """The headline metrics (:data:`COLUMNS`) of one video's summed counts."""
        metrics = metrics_from_counts(dict(counts))
        return {name: metrics[name] for name in COLUMNS}

    def score_files(self, folder: str | os.PathLike, sequences: list[str]) -> ScoreReport:
        """Score ``<folder>/<video>.npz`` files: per video, and their mean."""
        per_sequence = {}
        for name in sequences:
            path = Path(folder) / f"{name}.npz"
            results = read_results(path, self.load(name).num_frames)
            per_sequence[name] = self.score_sequence(name, results, path)
        combined = mean_over_videos(per_sequence) if per_sequence else {}
        return ScoreReport(self.name, per_sequence, combined,
                           scores={**per_sequence, COMBINED: combined})
