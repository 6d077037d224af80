"""The YouTube-VIS 2019 benchmark: track mAP (AP, AP50, AP75, AR)."""

from __future__ import annotations

import os
from pathlib import Path

from unitrack_env.benchmarks.base import Benchmark, data_root, text_digest
from unitrack_env.benchmarks.views import (
    LETTERBOX,
    ReportView,
    ScorecardColumn,
    association_head,
    iou_baseline,
)
from unitrack_env.datasets.youtube_vis import (
    VisTrack,
    YouTubeVISDataset,
    format_results,
    parse_vis_results,
)
from unitrack_env.errors import DataFormatError
from unitrack_env.io import atomic_write_text
from unitrack_env.metrics.events_mot import EventRows
from unitrack_env.metrics.events_vis import vis_sequence_events
from unitrack_env.metrics.report import ScoreReport
from unitrack_env.metrics.vis import score_videos

#: Name of the rule set in score reports (and the data folder under ``$UNITRACK_DATA``).
BENCHMARK = "YouTube-VIS-2019"


class VISBenchmark(Benchmark):
    """YouTube-VIS track mAP, per video and combined.

    ``results`` of one video: its tracks as :class:`~unitrack_env.datasets.youtube_vis.VisTrack`
    entries, written as ``<folder>/<video>.json`` (this video's entries of the official
    results JSON; :func:`unitrack_env.metrics.vis.merge_result_files` joins them).
    """

    task = "vis"
    columns = ("AP", "AP50", "AP75", "AR")
    report_view = ReportView(lanes=("fn", "fp"), unit="track-frames",
                             value=("iou", "IoU of tp tracks"), value_type="tp")
    no_intervals = "track mAP ranks whole tracks; it is not a mean over frames"
    scorecard = ScorecardColumn(
        "VIS", ("UniTrack/VIS-v0",), (association_head(("AP", "AP50")),),
        iou_baseline(("AP", "AP50")), ("UniTrack", "AP"), order=7, input_size=LETTERBOX)

    @classmethod
    def build(cls, root: str | os.PathLike | None = None, split: str = "train",
              detections: str | os.PathLike = "public",
              annotation_file: str | os.PathLike | None = None) -> VISBenchmark:
        """The benchmark of ``VISEnv(root=, split=, annotation_file=)``."""
        path, synthetic = data_root(root, BENCHMARK, BENCHMARK, kind="youtube_vis")
        return cls(YouTubeVISDataset(path, split, detections, annotation_file),
                   synthetic=synthetic)

    @property
    def name(self) -> str:
        """``"YouTube-VIS-2019"``."""
        return BENCHMARK

    def sequence_length(self, name: str) -> int:
        """Number of frames of video ``name``."""
        return self.dataset.video(name).length

    def has_ground_truth(self, name: str) -> bool:
        """Whether the split has annotations."""
        return self.dataset.has_annotations

    def write(self, folder: str | os.PathLike, sequence: str, results: list[VisTrack]) -> None:
        """Write ``<folder>/<video>.json``: this video's entries of the results JSON."""
        atomic_write_text(Path(folder) / f"{sequence}.json", format_results(results))

    def read(self, folder: str | os.PathLike, sequence: str) -> list[VisTrack]:
        """Read ``<folder>/<video>.json`` back as tracks of that video."""
        video = self.dataset.video(sequence)
        path = Path(folder) / f"{video.name}.json"
        if not path.is_file():
            raise DataFormatError(path, f"result file for video '{video.name}' is missing")
        return parse_vis_results(path, {video.id: video})

    def digest(self, results: list[VisTrack]) -> str:
        """SHA-256 of the video's results JSON."""
        return text_digest(format_results(results))

    def score_sequence(self, sequence: str, results: list[VisTrack]) -> dict[str, float]:
        """Track mAP of one video's tracks (the split must have annotations)."""
        video = self.dataset.video(sequence)
        return score_videos(self.dataset.data, results, [video]).per_sequence[video.name]

    def score_files(self, folder: str | os.PathLike, sequences: list[str]) -> ScoreReport:
        """Track mAP of ``<folder>/<video>.json`` files, per video and combined."""
        videos = [self.dataset.video(name) for name in dict.fromkeys(sequences)]
        results: list[VisTrack] = []
        for video in videos:
            results += self.read(folder, video.name)
        return score_videos(self.dataset.data, results, videos, source=Path(folder))

    def sequence_events(self, folder: str | os.PathLike, sequence: str) -> EventRows:
        """Per-frame events of the tracks matched to the video's instances (IoU of tp)."""
        return vis_sequence_events(sequence, self.dataset.data, self.read(folder, sequence),
                                   self.dataset.video(sequence))
