"""Official YouTube-VIS track mAP through TrackEval 1.3.0 (``YouTubeVIS`` + ``TrackMAP``).

TrackEval (J. Luiten, A. Hoffhues et al., https://github.com/JonathonLuiten/TrackEval, MIT
licence) restates the YouTube-VIS evaluation (Yang et al., ICCV 2019): tracks match by
spatio-temporal mask IoU (intersections and unions summed over the video's frames); AP is
averaged over IoU 0.50:0.05:0.95 and 101 recall points per category, then over categories.
Its classes are called directly in a private temporary folder (no ``Evaluator``: nothing is
printed, plotted or written). The combined row accumulates all videos before averaging, as
the leaderboard does (docs/evaluation.md). ``AP`` is ``AP_all``, the challenge's mAP;
undefined values are -1, TrackEval's convention.
"""

from __future__ import annotations

import contextlib
import io
import json
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from unitrack_env.datasets.rle import quiet_pycocotools
from unitrack_env.datasets.youtube_vis import (
    VisData,
    VisTrack,
    VisVideo,
    format_annotations,
    format_results,
)
from unitrack_env.errors import DataFormatError
from unitrack_env.metrics.report import COMBINED, ScoreReport

#: Split name used inside the temporary TrackEval layout.
_SPLIT = "eval"
_TRACKER = "tracker"
#: Index of IoU 0.50 and 0.75 in TrackEval's thresholds 0.50:0.05:0.95.
IOU50_INDEX, IOU75_INDEX = 0, 5


#: TrackMAP's area ranges for YouTube-VIS (TrackEval's ``scripts/run_youtube_vis.py``):
#: small < 128^2, medium < 256^2, large, in pixels; time ranges are off there (YouTube-VIS
#: gives no track lengths).
AREA_RANGES = ([0**2, 128**2], [128**2, 256**2], [256**2, 1e5**2])


def _metric() -> Any:
    # lazy: optional dependency (trackeval, installed on its own with --no-deps)
    from trackeval.metrics import TrackMAP

    return TrackMAP({"PRINT_CONFIG": False, "USE_TIME_RANGES": False,
                     "AREA_RANGES": [list(r) for r in AREA_RANGES]})


def _flatten(res: dict[str, Any]) -> dict[str, float]:
    out: dict[str, float] = {}
    for name, value in res.items():
        if name.startswith(("AP_", "AR_")):
            arr = np.asarray(value, dtype=np.float64)
            out[name] = -1.0 if (arr <= -1).all() else float(np.mean(arr))
    ap = np.asarray(res["AP_all"], dtype=np.float64)
    out["AP"] = out["AP_all"]
    out["AP50"] = float(ap[IOU50_INDEX])
    out["AP75"] = float(ap[IOU75_INDEX])
    out["AR"] = out["AR_all"]
    return out


def _per_class(ground_truth: VisData, results: list[VisTrack], videos: list[VisVideo],
               source: Path | None, metric: Any) -> dict[str, dict[str, Any]]:
    """TrackMAP's ``eval_sequence`` result of every class and video, ``{class: {video: res}}``.

    TrackEval numbers the result tracks of the videos from 0 in file order (its
    ``global_tid_counter``); with one video, a track's id is its index in ``results``.
    """
    if ground_truth.tracks is None:
        raise ValueError(f"{ground_truth.path} has no annotations to score against")
    if not videos:
        raise ValueError("no videos to score")
    # lazy: optional dependency (trackeval, installed on its own with --no-deps)
    import trackeval.datasets as te_datasets
    from trackeval.utils import TrackEvalException

    ids = {v.id for v in videos}
    kept = [r for r in results if r.video_id in ids]
    with tempfile.TemporaryDirectory(prefix="unitrack-vis-") as tmp:
        gt_dir = Path(tmp) / "gt" / f"youtube_vis_{_SPLIT}"
        gt_dir.mkdir(parents=True)
        (gt_dir / "gt.json").write_text(format_annotations(ground_truth, list(videos)))
        trk_dir = Path(tmp) / "trk" / f"youtube_vis_{_SPLIT}" / _TRACKER / "data"
        trk_dir.mkdir(parents=True)
        (trk_dir / "results.json").write_text(format_results(kept))
        config = {"GT_FOLDER": str(Path(tmp) / "gt") + "/",
                  "TRACKERS_FOLDER": str(Path(tmp) / "trk") + "/",
                  "OUTPUT_FOLDER": tmp, "TRACKERS_TO_EVAL": [_TRACKER], "SPLIT_TO_EVAL": _SPLIT,
                  "PRINT_CONFIG": False, "CLASSES_TO_EVAL": None}
        captured = io.StringIO()
        per_class: dict[str, dict[str, Any]] = {}
        try:
            with contextlib.redirect_stdout(captured), contextlib.redirect_stderr(captured), \
                    quiet_pycocotools():  # TrackEval decodes the masks with pycocotools
                dataset = te_datasets.YouTubeVIS(config)
                for seq in dataset.seq_list:
                    raw = dataset.get_raw_seq_data(_TRACKER, seq)
                    for cls in dataset.class_list:
                        data = dataset.get_preprocessed_seq_data(raw, cls)
                        per_class.setdefault(cls, {})[seq] = metric.eval_sequence(data)
        except TrackEvalException as exc:
            raise DataFormatError(source or Path("<results>"),
                                  f"TrackEval rejected the data: {exc}") from exc
    return per_class


def score_videos(ground_truth: VisData, results: list[VisTrack], videos: list[VisVideo], *,
                 source: Path | None = None) -> ScoreReport:
    """Track mAP of ``results`` on ``videos`` of ``ground_truth``, per video and combined.

    Raises ValueError on empty input, DataFormatError (naming ``source``) on rejected data.
    """
    metric = _metric()
    per_class = _per_class(ground_truth, results, videos, source, metric)
    seqs = [v.name for v in videos]
    per_sequence = {}
    for seq in seqs:
        classes = {cls: metric.combine_sequences({seq: res[seq]}) for cls, res in per_class.items()}
        per_sequence[seq] = _flatten(metric.combine_classes_class_averaged(classes))
    combined = metric.combine_classes_class_averaged(
        {cls: metric.combine_sequences(res) for cls, res in per_class.items()})
    return ScoreReport(benchmark="YouTube-VIS-2019", per_sequence=per_sequence,
                       combined=_flatten(combined), scores={COMBINED: combined})


@dataclass(frozen=True)
class TrackMatch:
    """TrackEval's matching of one video's tracks of one class at one IoU threshold.

    ``dt_index`` orders the result tracks as TrackEval does (score descending); ``dt_gt`` is
    the annotation each matches (-1 if none); ``*_ignored`` marks crowd/out-of-range tracks.
    """

    category_id: int
    dt_index: tuple[int, ...]
    dt_gt: tuple[int, ...]
    dt_ignored: tuple[bool, ...]
    gt_ids: tuple[int, ...]
    gt_matched: tuple[bool, ...]
    gt_ignored: tuple[bool, ...]


def track_matches(ground_truth: VisData, results: list[VisTrack], video: VisVideo, *,
                  threshold_index: int = IOU50_INDEX) -> list[TrackMatch]:
    """Per class, the matching behind one video's AP at one IoU threshold (default 0.50).

    The matching of the ``all`` area range, read from TrackEval's ``TrackMAP``.
    """
    by_name = {name: cid for cid, name in ground_truth.categories.items()}
    results = [r for r in results if r.video_id == video.id]
    out = []
    for cls, seqs in _per_class(ground_truth, results, [video], None, _metric()).items():
        res = seqs[video.name][0]
        if res is None:
            continue
        out.append(TrackMatch(
            by_name[cls], tuple(int(i) for i in res["dt_ids"]),
            tuple(int(g) for g in np.asarray(res["dt_matches"])[threshold_index]),
            tuple(bool(v) for v in np.asarray(res["dt_ignore"])[threshold_index]),
            tuple(int(g) for g in res["gt_ids"]),
            tuple(bool(m > -1) for m in np.asarray(res["gt_matches"])[threshold_index]),
            tuple(bool(v) for v in res["gt_ignore"])))
    return out


def merge_result_files(folder: str | Path, sequences: list[str] | None = None) -> list[dict]:
    """Concatenate per-video result files ``<folder>/<video>.json`` into one results list.

    The list is what the challenge's ``results.json`` holds (dump it with ``json.dump``).
    """
    folder = Path(folder)
    names = sequences if sequences is not None else sorted(p.stem for p in folder.glob("*.json"))
    out: list[dict] = []
    for name in names:
        path = folder / f"{name}.json"
        try:
            out += json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise DataFormatError(path, f"result file for video '{name}' is missing") from None
        except json.JSONDecodeError as exc:
            raise DataFormatError(path, f"not valid JSON ({exc.msg})", line=exc.lineno) from None
    return out
