"""The spread of a run's metrics over its repetitions (``unitrack evaluate --repeats K``).

Each sequence is played ``K`` times in a row by the same agent; the benchmark writes every
repetition (:meth:`~unitrack_env.benchmarks.base.Benchmark.write_repetitions`: GOT-10k's
``<seq>_001.txt`` ... ``<seq>_00K.txt``, elsewhere ``data/repeat-00k/`` beside repetition 1
in ``data/``) and scores each alone
(:meth:`~unitrack_env.benchmarks.base.Benchmark.score_repetition`). The run's own scores stay
the benchmark's official ones (repetition 1; GOT-10k pools every repetition's frames, as its
toolkit does).
"""

from __future__ import annotations

import math
import os
from typing import Any

from unitrack_env.benchmarks.base import Benchmark

#: The statistics of a metric over repetitions, in the order tables show them.
SPREAD_STATS = ("mean", "min", "max")


def spread(rows: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """``{metric: {"mean", "min", "max"}}`` over ``rows`` (one metrics dict per repetition).

    Metrics that are not numbers are left out; a metric undefined (NaN) in some
    repetitions is taken over the others (NaN when it is undefined in all).
    """
    out: dict[str, dict[str, float]] = {}
    for metric in rows[0] if rows else {}:
        values = [row.get(metric) for row in rows]
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
            continue
        finite = [float(v) for v in values if math.isfinite(v)]
        if not finite:
            out[metric] = dict.fromkeys(SPREAD_STATS, math.nan)
            continue
        out[metric] = {"mean": sum(finite) / len(finite), "min": min(finite),
                       "max": max(finite)}
    return out


def repetition_scores(bench: Benchmark, folder: str | os.PathLike, sequences: list[str],
                      repeats: int) -> dict[str, Any]:
    """Every repetition's scores and their spread, as ``metrics.json`` stores them.

    ``{"repeats": K, "combined": [K dicts], "per_sequence": {seq: [K dicts]},
    "spread": {"combined": {metric: {mean, min, max}}, "per_sequence": {seq: {...}}}}``.
    """
    reports = [bench.score_repetition(folder, sequences, k) for k in range(1, repeats + 1)]
    combined = [report.combined for report in reports]
    per_sequence = {name: [report.per_sequence[name] for report in reports]
                    for name in reports[0].per_sequence}
    return {"repeats": repeats, "combined": combined, "per_sequence": per_sequence,
            "spread": {"combined": spread(combined),
                       "per_sequence": {name: spread(rows) for name, rows in per_sequence.items()}}}
