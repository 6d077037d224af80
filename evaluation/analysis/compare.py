"""Paired comparison of two runs with confidence intervals.

The default is a paired delete-a-block jackknife (Künsch 1989, Ann. Statist. 17, 1217-1241)
with a t interval: each replicate leaves the same block of consecutive frames (a fifth of a
sequence; at least 50 frames for frame-scored tasks) out of both runs and recomputes the
metrics from per-frame statistics (:mod:`unitrack_env.metrics.mot_stats` says which are
exact). It replaced a block bootstrap, kept as ``percentile``, ``bc`` and ``basic`` for
comparison: resampling with replacement duplicates pieces of identities, and for the
association metrics (IDF1, AssA, HOTA: a whole identity is matched once) the bootstrap saw only
0.53-0.72 of the true spread at every block length; leaving blocks out duplicates nothing.
Method, coverage by simulation and the commands: docs/report.md. Two run folders are compared
by :func:`.intervals.compare_runs`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.stats import norm as NORMAL
from scipy.stats import t as STUDENT

from unitrack_env.metrics.mot_stats import (
    MOT_STAT_METRICS,
    MotStats,
    add_sums,
    metrics_from_sums,
    weighted_sums,
)

from .events import run_benchmark

#: Row name of the combined comparison.
COMBINED: str = "COMBINED"

#: Blocks per sequence of the block jackknife (its block length is a fifth of the sequence).
BLOCKS: int = 5

#: A sequence needs this many frames (blocks of 20) for an interval worth reading.
MIN_FRAMES: int = 100


def block_length(num_frames: int) -> int:
    """The block length used for a sequence of ``num_frames``: a fifth of it.

    Association metrics (IDF1, AssA, HOTA) depend on whole identities, which last tens to
    hundreds of frames; blocks shorter than that understate their variance (docs/report.md).
    """
    return max(1, math.ceil(int(num_frames) / BLOCKS))


#: Shortest block of a frame-scored task's jackknife, in frames: a tracker that loses its
#: target stays lost for tens of frames, and shorter blocks understate the variance
#: (coverage 81-90% with blocks of a fifth of 100-200 frames, 93-97% with at least 50:
#: benchmarks/compare_coverage_frames.py, docs/report.md).
MIN_FRAME_BLOCK: int = 50


def frame_block_length(num_frames: int) -> int:
    """Block length of a frame-scored sequence: a fifth of it, but at least 50 frames.

    Never more than half the sequence (two blocks), so a short sequence keeps a spread.
    """
    n = int(num_frames)
    return max(block_length(n), min(MIN_FRAME_BLOCK, math.ceil(n / 2)))


def jackknife_weights(num_frames: int, length: int) -> np.ndarray:
    """``(k, num_frames)`` frame weights: row ``j`` leaves out the ``j``-th block of ``length``."""
    n, ell = int(num_frames), max(1, int(length))
    k = math.ceil(n / ell)
    weights = np.ones((k, n))
    for j in range(k):
        weights[j, j * ell:(j + 1) * ell] = 0.0
    return weights


def block_weights(num_frames: int, resamples: int, rng: np.random.Generator,
                  length: int | None = None) -> np.ndarray:
    """``(resamples, num_frames)`` circular-block-bootstrap frame counts (rows sum to F)."""
    n = int(num_frames)
    ell = block_length(n) if length is None else max(1, min(int(length), n))
    blocks = math.ceil(n / ell)
    starts = rng.integers(0, n, size=(resamples, blocks))
    idx = (starts[:, :, None] + np.arange(ell)[None, None, :]).reshape(resamples, -1)[:, :n] % n
    weights = np.zeros((resamples, n))
    np.add.at(weights, (np.repeat(np.arange(resamples), n), idx.ravel()), 1.0)
    return weights


@dataclass
class MetricDiff:
    """One metric of one row: both values, the difference ``a - b`` and its interval."""

    a: float
    b: float
    diff: float
    low: float
    high: float
    reliable: bool = True

    @property
    def significant(self) -> bool:
        """Whether the 95% interval excludes 0 and rests on enough data to say so."""
        return self.reliable and (self.low > 0 or self.high < 0)


@dataclass
class Comparison:
    """Per-sequence and combined paired differences of two runs."""

    run_a: str
    run_b: str
    rows: dict[str, dict[str, MetricDiff]]
    frames: dict[str, int]
    blocks: dict[str, int]
    resamples: int
    level: str
    notes: list[str] = field(default_factory=list)
    method: str = "jackknife"

    def to_json(self) -> dict:
        """A JSON-friendly form."""
        return {"run_a": self.run_a, "run_b": self.run_b, "resamples": self.resamples,
                "level": self.level, "method": self.method, "frames": self.frames,
                "block_length": self.blocks,
                "notes": self.notes,
                "rows": {r: {m: vars(d) for m, d in row.items()} for r, row in self.rows.items()}}


def compare_stats(stats_a: dict[str, MotStats], stats_b: dict[str, MotStats], *,
                  resamples: int = 1000, seed: int = 0, level: str = "frames",
                  block: int | None = None,
                  method: str = "jackknife") -> tuple[dict[str, dict[str, MetricDiff]], dict]:
    """Paired intervals from per-sequence statistics; returns ``(rows, block lengths)``.

    ``jackknife`` (the default) is the delete-a-block jackknife with a t interval;
    ``percentile``, ``bc`` and ``basic`` are block-bootstrap intervals (``resamples``, ``seed``).
    """
    if level not in ("frames", "sequences"):
        raise ValueError(f"level must be 'frames' or 'sequences', got {level!r}")
    if method not in INTERVALS:
        raise ValueError(f"interval must be one of {INTERVALS}, got {method!r}")
    blocks = {name: block_length(s.num_frames) if block is None
              else max(1, min(int(block), s.num_frames)) for name, s in stats_a.items()}
    if method == "jackknife":
        return _jackknife_rows(stats_a, stats_b, blocks, level), blocks
    return _bootstrap_rows(stats_a, stats_b, blocks, level, resamples, seed, method), blocks


def _point(stats: MotStats) -> dict[str, np.ndarray]:
    return weighted_sums(stats, np.ones((1, stats.num_frames)))


def _swap(total: dict, part: dict, replacement: dict) -> dict:
    """Combined sums with one sequence's ``part`` replaced (broadcast over replicates)."""
    return {key: total[key] - part[key] + replacement[key] for key in total}


def _jackknife_rows(stats_a: dict[str, MotStats], stats_b: dict[str, MotStats],
                    blocks: dict[str, int], level: str) -> dict[str, dict[str, MetricDiff]]:
    names = list(stats_a)
    pa, pb = [_point(stats_a[n]) for n in names], [_point(stats_b[n]) for n in names]
    ta, tb = add_sums(pa), add_sums(pb)
    rows: dict[str, dict[str, MetricDiff]] = {}
    reps_a, reps_b = [], []
    for i, name in enumerate(names):
        w = jackknife_weights(stats_a[name].num_frames, blocks[name])
        da, db = weighted_sums(stats_a[name], w), weighted_sums(stats_b[name], w)
        rows[name] = _diffs(pa[i], pb[i], da, db, "jackknife")
        if level == "frames":  # leave out one block of this sequence, keep the others
            reps_a.append(_swap(ta, pa[i], da))
            reps_b.append(_swap(tb, pb[i], db))
        else:  # leave out this whole sequence
            reps_a.append(_swap(ta, pa[i], {k: 0 * v for k, v in pa[i].items()}))
            reps_b.append(_swap(tb, pb[i], {k: 0 * v for k, v in pb[i].items()}))
    join = {k: np.concatenate([r[k] for r in reps_a]) for k in ta}
    join_b = {k: np.concatenate([r[k] for r in reps_b]) for k in tb}
    rows[COMBINED] = _diffs(ta, tb, join, join_b, "jackknife")
    return rows


def _bootstrap_rows(stats_a: dict[str, MotStats], stats_b: dict[str, MotStats],
                    blocks: dict[str, int], level: str, resamples: int, seed: int,
                    method: str) -> dict[str, dict[str, MetricDiff]]:
    rng = np.random.default_rng(seed)
    names = list(stats_a)
    rows: dict[str, dict[str, MetricDiff]] = {}
    parts_a, parts_b, points_a, points_b = [], [], [], []
    for name in names:
        w = block_weights(stats_a[name].num_frames, resamples, rng, blocks[name])
        sa, sb = weighted_sums(stats_a[name], w), weighted_sums(stats_b[name], w)
        pa, pb = _point(stats_a[name]), _point(stats_b[name])
        parts_a.append(sa)
        parts_b.append(sb)
        points_a.append(pa)
        points_b.append(pb)
        rows[name] = _diffs(pa, pb, sa, sb, method)
    counts = None
    if level == "sequences":
        counts = rng.multinomial(len(names), np.full(len(names), 1 / len(names)), resamples)
    rows[COMBINED] = _diffs(add_sums(points_a), add_sums(points_b),
                            add_sums(parts_a, counts), add_sums(parts_b, counts), method)
    return rows


#: Interval methods: the block jackknife's t interval (the default), and the block
#: bootstrap's percentile, basic (reflected) and bias-corrected percentile intervals.
INTERVALS: tuple[str, ...] = ("jackknife", "percentile", "bc", "basic")


def jackknife_interval(point: float, replicates: np.ndarray) -> tuple[float, float]:
    """``point`` plus or minus ``t(k - 1)`` jackknife standard errors of ``k`` replicates.

    The replicates are the statistic with one block left out each; the t quantile with
    ``k - 1`` degrees of freedom widens the interval when there are few blocks. With fewer
    than two replicates there is no spread to measure and the interval is the point.
    """
    k = len(replicates)
    if k < 2:
        return point, point
    se = math.sqrt((k - 1) / k * float(np.sum((replicates - replicates.mean()) ** 2)))
    q = float(STUDENT.ppf(0.975, k - 1))
    return point - q * se, point + q * se


def interval(point: float, boot: np.ndarray, method: str = "percentile") -> tuple[float, float]:
    """The 95% interval of ``point`` from its replicates ``boot``.

    ``jackknife``: :func:`jackknife_interval` of leave-one-block-out replicates. For bootstrap
    replicates: ``percentile`` is their 2.5-97.5 percentiles; ``bc`` shifts them by the
    bootstrap's median bias (Efron's bias-corrected percentile) and ``basic`` reflects them
    around ``point``. Their coverage is measured by ``benchmarks/compare_coverage.py``.
    """
    if method == "jackknife":
        return jackknife_interval(point, boot)
    if method == "percentile":
        low, high = np.percentile(boot, [2.5, 97.5])
    elif method == "basic":
        q_low, q_high = np.percentile(boot, [2.5, 97.5])
        low, high = 2 * point - q_high, 2 * point - q_low
    elif method == "bc":
        below = (np.sum(boot < point) + 0.5 * np.sum(boot == point)) / len(boot)
        z0 = NORMAL.ppf(min(max(below, 0.5 / len(boot)), 1 - 0.5 / len(boot)))
        levels = NORMAL.cdf(2 * z0 + np.array([-1.959964, 1.959964]))
        low, high = np.percentile(boot, 100 * levels)
    else:
        raise ValueError(f"interval must be one of {INTERVALS}, got {method!r}")
    return float(low), float(high)


def _diffs(point_a: dict, point_b: dict, boot_a: dict, boot_b: dict,
           method: str = "percentile") -> dict[str, MetricDiff]:
    ma, mb = metrics_from_sums(point_a), metrics_from_sums(point_b)
    ba, bb = metrics_from_sums(boot_a), metrics_from_sums(boot_b)
    out = {}
    for name in MOT_STAT_METRICS:
        point = float(ma[name][0] - mb[name][0])
        low, high = interval(point, ba[name] - bb[name], method)
        out[name] = MetricDiff(float(ma[name][0]), float(mb[name][0]), point, low, high)
    return out


def run_stats(run: str | os.PathLike, sequences: list[str],
              cls: str | None = None) -> dict[str, MotStats]:
    """Per-sequence statistics of a run folder, from its result files and ground truth.

    For a benchmark whose ``intervals`` are ``"stats"`` (box MOT):
    :meth:`~unitrack_env.benchmarks.base.Benchmark.frame_stats` (of one class ``cls``).
    """
    bench = run_benchmark(run)
    if bench.intervals != "stats":
        raise ValueError(f"{run}: the {bench.task} benchmark {bench.name} has no per-frame "
                         "statistics to recompute its metrics from")
    if cls is not None:
        return {name: bench.frame_stats(Path(run) / "data", name, cls) for name in sequences}
    return {name: bench.frame_stats(Path(run) / "data", name) for name in sequences}


def _block_count(frames: dict[str, int], blocks: dict[str, int]) -> dict[str, int]:
    return {name: math.ceil(n / blocks[name]) for name, n in frames.items()}


def unreliable_rows(frames: dict[str, int], blocks: dict[str, int], *,
                    pooled: bool = False) -> list[str]:
    """Rows whose interval rests on too little data.

    A sequence needs :data:`MIN_FRAMES` frames in at least :data:`BLOCKS` blocks. The
    combined row needs one such sequence, or with ``pooled`` (frame-scored tasks, whose
    combined replicates pool the blocks of all sequences) :data:`BLOCKS` blocks of at least
    :data:`MIN_FRAME_BLOCK` frames in all.
    """
    counts = _block_count(frames, blocks)
    out = [name for name, count in counts.items()
           if count < BLOCKS or frames[name] < MIN_FRAMES]
    if pooled:  # enough blocks long enough (MIN_FRAME_BLOCK) in all
        long = sum(c for name, c in counts.items() if blocks[name] >= MIN_FRAME_BLOCK)
        enough = long >= BLOCKS and sum(frames.values()) >= MIN_FRAMES
    else:
        enough = len(out) < len(counts)
    return out + ([] if enough else [COMBINED])


def few_data_notes(frames: dict[str, int], blocks: dict[str, int], level: str, *,
                   pooled: bool = False) -> list[str]:
    """Plain warnings where too little data makes the intervals wide or unreliable."""
    notes = []
    counts = _block_count(frames, blocks)
    for name in unreliable_rows(frames, blocks, pooled=pooled):
        if name == COMBINED:
            rule = (f"fewer than {BLOCKS} blocks of {MIN_FRAME_BLOCK} frames" if pooled else
                    f"no sequence with {MIN_FRAMES} frames in {BLOCKS} blocks")
            notes.append(f"{COMBINED}: {sum(frames.values())} frames in all, {rule}: too "
                         "little data for a trustworthy interval; do not read a difference "
                         "into it")
        else:
            notes.append(f"{name}: only {frames[name]} frames ({counts[name]} blocks of "
                         f"{blocks[name]}): too little data, its interval is not trustworthy "
                         "(so few frames cannot show how much the difference varies)")
    if level == "sequences" and len(frames) < 10:
        notes.append(f"leaving out one of {len(frames)} sequences at a time: the "
                     "sequence-level interval is wide and unstable with fewer than 10 sequences")
    return notes
