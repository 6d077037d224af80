"""Official MOTChallenge scores through TrackEval 1.3.0 (HOTA, CLEAR, Identity, Count).

TrackEval (J. Luiten, A. Hoffhues et al., https://github.com/JonathonLuiten/TrackEval, MIT
licence) is the MOTChallenge leaderboards' scorer. We call its ``MotChallenge2DBox``
(``get_raw_seq_data``, ``get_preprocessed_seq_data``) and each metric's ``eval_sequence`` /
``combine_sequences``, not its ``Evaluator``, so nothing is printed, plotted or written (its
defaults write into its own ``site-packages`` folder). Result rows go to a private temporary
folder with track ids relabelled to ``1..K``: TrackEval relabels too, but indexes an array by
the raw id, so huge or negative ids would exhaust memory or alias. The HOTA family (HOTA, DetA,
AssA, LocA, ...) is the mean over the 19 alpha thresholds, as TrackEval's summary reports it.
"""

from __future__ import annotations

import configparser
import contextlib
import io
import os
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from unitrack_env.errors import DataFormatError
from unitrack_env.metrics.mot_preprocess import normalize_benchmark
from unitrack_env.metrics.mot_results import (
    MIN_RESULT_COLUMNS,
    parse_result_file,
    validate_tracker_rows,
    write_for_trackeval,
)
from unitrack_env.metrics.report import COMBINED, ScoreReport

__all__ = [
    "METRIC_NAMES",
    "RESULT_SUFFIX",
    "SequenceScore",
    "combine_sequence_scores",
    "combine_sequences",
    "flatten_results",
    "score_folder",
    "score_sequence",
    "trackeval_metrics",
    "trackeval_sequence_data",
]

_TRACKER_NAME: str = "tracker"  # folders of the temporary TrackEval layout
_TRACKER_SUB_FOLDER: str = "data"
_CLASS: str = "pedestrian"  # the only MOTChallenge class that is evaluated

#: Order in which metrics appear in summaries (TrackEval class names).
METRIC_NAMES: tuple[str, ...] = ("HOTA", "CLEAR", "Identity", "Count")


@dataclass(frozen=True, eq=False)
class SequenceScore(Mapping[str, float]):
    """TrackEval's results for one sequence (or a combination of sequences).

    A read-only mapping over ``summary`` (every scalar TrackEval field, HOTA arrays averaged
    over alpha); ``raw`` holds TrackEval's result dicts per metric class as returned.
    """

    sequence: str
    benchmark: str
    summary: dict[str, float]
    raw: dict[str, dict[str, Any]] = field(repr=False)

    def __getitem__(self, key: str) -> float:
        return self.summary[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.summary)

    def __len__(self) -> int:
        return len(self.summary)


def trackeval_metrics() -> list[Any]:
    """Fresh, quiet TrackEval HOTA, CLEAR, Identity and Count metric objects."""
    # lazy: optional dependency (trackeval, installed on its own with --no-deps)
    from trackeval.metrics import CLEAR, HOTA, Count, Identity

    quiet = {"PRINT_CONFIG": False}
    return [HOTA(), CLEAR(dict(quiet)), Identity(dict(quiet)), Count()]


def trackeval_sequence_data(
    dataset_class: Any, config: dict[str, Any], tracker: str, seq: str, cls: str,
    captured: io.StringIO,
) -> dict[str, Any]:
    """TrackEval's preprocessed data of one sequence, with its printing kept in ``captured``.

    The redirection is process-wide while it lasts: score in worker processes, not threads.
    """
    with contextlib.redirect_stdout(captured), contextlib.redirect_stderr(captured):
        dataset = dataset_class(config)
        raw_data = dataset.get_raw_seq_data(tracker, seq)
        return dataset.get_preprocessed_seq_data(raw_data, cls)


#: ``gt ids x tracker ids`` float64 matrices alive at once in TrackEval's HOTA: the potential
#: matches, their alignment score (and two temporaries building it), one per alpha (19).
_HOTA_MATRICES = 22


def _memory_bytes() -> int | None:
    """This machine's physical memory, or None where the OS does not say."""
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def check_matrix_memory(data: dict[str, Any], source: Path, seq: str) -> None:
    """Refuse to score when TrackEval's HOTA matrices could not fit this machine's memory.

    Names the culprit instead of a ``MemoryError: Unable to allocate 728. TiB``.
    """
    gt_ids, tracker_ids = int(data["num_gt_ids"]), int(data["num_tracker_ids"])
    need = _HOTA_MATRICES * 8 * gt_ids * tracker_ids
    memory = _memory_bytes()
    if memory is not None and need > memory:
        raise DataFormatError(
            source, f"{seq}: {tracker_ids:,} distinct track ids against {gt_ids:,} "
                    f"ground-truth ids; TrackEval's HOTA would allocate {need / 2**30:,.0f} GiB "
                    f"({_HOTA_MATRICES} matrices of gt x tracker ids), more than this "
                    f"machine's {memory / 2**30:,.0f} GiB. A tracker that starts a new id for "
                    "(almost) every detection? Keep ids across frames")


def flatten_results(raw: dict[str, dict[str, Any]]) -> dict[str, float]:
    """One flat dict of floats from TrackEval's per-metric results."""
    out: dict[str, float] = {}
    for metric in trackeval_metrics():
        res = raw[metric.get_name()]
        for name in metric.fields:
            if name not in res:
                continue
            if name in metric.integer_array_fields:
                continue  # per-alpha counts (HOTA_TP, ...) stay in ``raw``
            value = res[name]
            out[name] = float(np.mean(value)) if np.ndim(value) else float(value)
    return out


def _read_seq_length(gt_seq_dir: Path) -> int:
    ini = gt_seq_dir / "seqinfo.ini"
    if not ini.is_file():
        raise DataFormatError(ini, "missing; pass seq_length= when a sequence has no seqinfo.ini")
    parser = configparser.ConfigParser()
    try:
        parser.read(ini, encoding="utf-8")
        value = parser["Sequence"]["seqLength"]
    except (configparser.Error, KeyError, UnicodeDecodeError):
        raise DataFormatError(
            ini, "needs a [Sequence] section with seqLength", field="seqLength"
        ) from None
    try:
        length = int(value)
    except ValueError:
        raise DataFormatError(ini, f"{value!r} is not an integer", field="seqLength") from None
    if length < 1:
        raise DataFormatError(ini, f"must be positive, got {length}", field="seqLength")
    return length


def score_sequence(
    gt_seq_dir: str | Path,
    tracker_rows: np.ndarray | str | Path,
    *,
    benchmark: str,
    seq_length: int | None = None,
) -> SequenceScore:
    """Score one sequence with TrackEval's HOTA, CLEAR, Identity and Count metrics.

    ``gt_seq_dir`` holds ``gt/gt.txt``; ``tracker_rows`` are ``(k, >=6)`` rows or a result
    file; ``seq_length`` defaults to ``seqinfo.ini``'s. Bad files raise DataFormatError.
    """
    name = normalize_benchmark(benchmark)
    seq_dir = Path(gt_seq_dir).resolve()
    gt_file = seq_dir / "gt" / "gt.txt"
    if not gt_file.is_file():
        raise DataFormatError(gt_file, "ground truth not found (expected <sequence>/gt/gt.txt)")
    if seq_length is None:
        seq_length = _read_seq_length(seq_dir)
    elif int(seq_length) < 1:
        raise ValueError(f"seq_length must be positive, got {seq_length}")
    seq_length = int(seq_length)

    source: Path | None = None
    line_numbers: np.ndarray | None = None
    if isinstance(tracker_rows, (str, Path)):
        source = Path(tracker_rows)
        rows, line_numbers = parse_result_file(source)
    else:
        rows = np.asarray(tracker_rows, dtype=np.float64)
        if rows.size == 0:
            rows = rows.reshape(0, MIN_RESULT_COLUMNS)
    validate_tracker_rows(rows, seq_length, source, line_numbers)

    raw = _run_trackeval(seq_dir, rows, name, seq_length, gt_file, source)
    return SequenceScore(sequence=seq_dir.name, benchmark=name, summary=flatten_results(raw),
                         raw=raw)


def _run_trackeval(
    seq_dir: Path, rows: np.ndarray, benchmark: str, seq_length: int, gt_file: Path,
    source: Path | None = None,
) -> dict[str, dict[str, Any]]:
    # lazy: optional dependency (trackeval, installed on its own with --no-deps)
    from trackeval.datasets import MotChallenge2DBox
    from trackeval.utils import TrackEvalException

    seq = seq_dir.name
    with tempfile.TemporaryDirectory(prefix="unitrack-trackeval-") as tmp:
        data_dir = Path(tmp) / _TRACKER_NAME / _TRACKER_SUB_FOLDER
        data_dir.mkdir(parents=True)
        write_for_trackeval(rows, data_dir / f"{seq}.txt")
        config = {
            "GT_FOLDER": str(seq_dir.parent),
            "TRACKERS_FOLDER": tmp,
            "OUTPUT_FOLDER": tmp,
            "TRACKERS_TO_EVAL": [_TRACKER_NAME],
            "CLASSES_TO_EVAL": [_CLASS],
            "BENCHMARK": benchmark,
            "SPLIT_TO_EVAL": "train",
            "INPUT_AS_ZIP": False,
            "PRINT_CONFIG": False,
            "DO_PREPROC": True,
            "TRACKER_SUB_FOLDER": _TRACKER_SUB_FOLDER,
            "OUTPUT_SUB_FOLDER": "",
            "SEQ_INFO": {seq: seq_length},
            "SKIP_SPLIT_FOL": True,
        }
        captured = io.StringIO()
        try:
            # TrackEval prints tracebacks on bad input; they go into our error instead.
            data = trackeval_sequence_data(MotChallenge2DBox, config, _TRACKER_NAME, seq, _CLASS,
                                           captured)
        except TrackEvalException as exc:
            detail = captured.getvalue().strip().splitlines()
            hint = f" ({detail[-1]})" if detail else ""
            raise DataFormatError(gt_file, f"TrackEval rejected the data: {exc}{hint}") from exc
        check_matrix_memory(data, source or Path(f"<results of {seq}>"), seq)
        return {metric.get_name(): metric.eval_sequence(data) for metric in trackeval_metrics()}


def combine_sequence_scores(scores: Mapping[str, SequenceScore]) -> SequenceScore:
    """Combine per-sequence results as each TrackEval metric's ``combine_sequences`` does."""
    if not scores:
        raise ValueError("no sequence scores to combine")
    benchmarks = {s.benchmark for s in scores.values()}
    if len(benchmarks) != 1:
        raise ValueError(f"cannot combine scores of different benchmarks: {sorted(benchmarks)}")
    raw = {
        metric.get_name(): metric.combine_sequences(
            {seq: s.raw[metric.get_name()] for seq, s in scores.items()}
        )
        for metric in trackeval_metrics()
    }
    return SequenceScore(
        sequence="COMBINED", benchmark=benchmarks.pop(), summary=flatten_results(raw), raw=raw
    )


def combine_sequences(scores: Mapping[str, SequenceScore]) -> dict[str, float]:
    """Flat combined metrics over sequences (TrackEval's ``COMBINED_SEQ`` row)."""
    return dict(combine_sequence_scores(scores).summary)


#: File suffix of MOTChallenge result files.
RESULT_SUFFIX: str = ".txt"


def _sequences_from_results(results_dir: Path) -> list[str]:
    return sorted(
        p.stem for p in results_dir.iterdir() if p.is_file() and p.suffix == RESULT_SUFFIX
    )


def score_folder(
    gt_root: str | Path,
    results_dir: str | Path,
    *,
    benchmark: str,
    sequences: Sequence[str] | None = None,
) -> ScoreReport:
    """Score ``results_dir/<seq>.txt`` against ``gt_root/<seq>/gt/gt.txt`` for each sequence.

    ``sequences`` defaults to every result file. A missing file or folder, or a malformed
    line, raises DataFormatError naming it.
    """
    name = normalize_benchmark(benchmark)
    gt_root = Path(gt_root)
    results_dir = Path(results_dir)
    if not gt_root.is_dir():
        raise DataFormatError(gt_root, "ground-truth folder not found")
    if not results_dir.is_dir():
        raise DataFormatError(results_dir, "is a file; --results takes the folder of result "
                                           "files" if results_dir.is_file() else
                              "results folder not found")

    seqs = _folder_sequences(gt_root, results_dir, sequences)
    scores = {
        seq: score_sequence(gt_root / seq, results_dir / f"{seq}{RESULT_SUFFIX}", benchmark=name)
        for seq in seqs
    }
    combined = combine_sequence_scores(scores)
    return ScoreReport(
        benchmark=name,
        per_sequence={seq: dict(score.summary) for seq, score in scores.items()},
        combined=dict(combined.summary),
        scores={**scores, COMBINED: combined},
    )


def _folder_sequences(
    gt_root: Path, results_dir: Path, sequences: Sequence[str] | None
) -> list[str]:
    """The sequences :func:`score_folder` scores, each with a result file and ground truth."""
    if sequences is None:
        seqs = _sequences_from_results(results_dir)
        if not seqs:
            inner = results_dir / "data"  # a run folder of `unitrack evaluate`
            hint = (f"; the run's result files are in {inner}"
                    if inner.is_dir() and _sequences_from_results(inner) else "")
            raise DataFormatError(results_dir,
                                  f"contains no result files (*{RESULT_SUFFIX}){hint}")
    else:
        seqs = list(dict.fromkeys(sequences))
        if not seqs:
            raise ValueError("sequences is empty; pass None to score every result file")
        for seq in seqs:
            result = results_dir / f"{seq}{RESULT_SUFFIX}"
            if not result.is_file():
                raise DataFormatError(result, f"result file for sequence '{seq}' is missing")
    for seq in seqs:
        gt_file = gt_root / seq / "gt" / "gt.txt"
        if not gt_file.is_file():
            splits = [gt_root / split for split in ("train", "test")
                      if (gt_root / split / seq / "gt" / "gt.txt").is_file()]
            hint = f"; the ground truth folder is the split folder {splits[0]}" if splits else ""
            raise DataFormatError(
                results_dir / f"{seq}{RESULT_SUFFIX}",
                f"sequence '{seq}' has no ground truth (expected {gt_file}){hint}",
            )
    return seqs
