"""Score a folder of MOTChallenge result files with TrackEval.

Layout (the one MOTChallenge submissions and TrackEval use)::

    gt_root/<seq>/gt/gt.txt        ground truth
    gt_root/<seq>/seqinfo.ini      sequence length
    results_dir/<seq>.txt          one result file per sequence

Each sequence is scored by :func:`unitrack_env.metrics.motchallenge.score_sequence` and the
sequences are combined as TrackEval combines them (its ``COMBINED_SEQ`` row).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from unitrack_env.errors import DataFormatError
from unitrack_env.metrics.mot_preprocess import normalize_benchmark
from unitrack_env.metrics.motchallenge import (
    SequenceScore,
    combine_sequence_scores,
    score_sequence,
)

#: Key of the combined row, as TrackEval's tables label it.
COMBINED: str = "COMBINED"

#: File suffix of MOTChallenge result files.
RESULT_SUFFIX: str = ".txt"


@dataclass
class ScoreReport:
    """Per-sequence and combined TrackEval metrics of one results folder.

    Attributes:
        benchmark: TrackEval benchmark used.
        per_sequence: ``{sequence: {field: value}}`` (fractions, not percent).
        combined: metrics over all sequences (TrackEval's ``COMBINED_SEQ``).
        scores: the full :class:`SequenceScore` objects (with TrackEval's raw results),
            including ``COMBINED``; not serialised by :meth:`to_json`.
    """

    benchmark: str
    per_sequence: dict[str, dict[str, float]]
    combined: dict[str, float]
    scores: dict[str, SequenceScore] = field(default_factory=dict, repr=False)

    def to_json(self, *, indent: int | None = 2) -> str:
        """Serialise benchmark, per-sequence and combined metrics as JSON text."""
        payload = {
            "benchmark": self.benchmark,
            "per_sequence": self.per_sequence,
            "combined": self.combined,
        }
        return json.dumps(payload, indent=indent, sort_keys=False)


def _sequences_from_results(results_dir: Path) -> list[str]:
    return sorted(
        p.stem for p in results_dir.iterdir() if p.is_file() and p.suffix == RESULT_SUFFIX
    )


def score_results(
    gt_root: str | Path,
    results_dir: str | Path,
    *,
    benchmark: str,
    sequences: Sequence[str] | None = None,
) -> ScoreReport:
    """Score ``results_dir/<seq>.txt`` against ``gt_root/<seq>/gt/gt.txt`` for each sequence.

    Args:
        gt_root: folder holding one MOTChallenge sequence folder per sequence.
        results_dir: folder of result files named ``<seq>.txt``.
        benchmark: ``"MOT15"``, ``"MOT16"``, ``"MOT17"`` or ``"MOT20"``.
        sequences: the sequences to score; each must have a result file.  By default every
            ``*.txt`` file in ``results_dir`` is scored (and each must have ground truth).

    Returns:
        A :class:`ScoreReport`.

    Raises:
        DataFormatError: a missing folder, a result file whose sequence has no ground truth, a
            missing result file for a listed sequence, or a malformed line (naming the file,
            line and field).
    """
    name = normalize_benchmark(benchmark)
    gt_root = Path(gt_root)
    results_dir = Path(results_dir)
    if not gt_root.is_dir():
        raise DataFormatError(gt_root, "ground-truth folder not found")
    if not results_dir.is_dir():
        raise DataFormatError(results_dir, "results folder not found")

    if sequences is None:
        seqs = _sequences_from_results(results_dir)
        if not seqs:
            raise DataFormatError(results_dir, f"contains no result files (*{RESULT_SUFFIX})")
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
            raise DataFormatError(
                results_dir / f"{seq}{RESULT_SUFFIX}",
                f"sequence '{seq}' has no ground truth (expected {gt_file})",
            )

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
