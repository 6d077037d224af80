"""Paired comparison of two runs with bootstrap confidence intervals.

More in docs/module-notes.md.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.stats import norm as NORMAL

from unitrack_env.metrics.events_mot import preprocessed_frames, read_gt_rows
from unitrack_env.metrics.mot_stats import (
    MOT_STAT_METRICS,
    MotStats,
    add_sums,
    metrics_from_sums,
    mot_stats,
    weighted_sums,
)

from .events import run_benchmark, run_sequences

#: Row name of the combined comparison.
COMBINED: str = "COMBINED"

#: Fewer blocks than this in a sequence makes its interval unreliable.
MIN_BLOCKS: int = 10


def block_length(num_frames: int) -> int:
    """The block length used for a sequence of ``num_frames`` (see the module docstring)."""
    rule = max(math.ceil(1.5 * num_frames ** (1 / 3)), math.ceil(num_frames / MIN_BLOCKS))
    return max(1, min(num_frames, rule))


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

    def to_json(self) -> dict:
        """A JSON-friendly form."""
        return {"run_a": self.run_a, "run_b": self.run_b, "resamples": self.resamples,
                "level": self.level, "frames": self.frames, "block_length": self.blocks,
                "notes": self.notes,
                "rows": {r: {m: vars(d) for m, d in row.items()} for r, row in self.rows.items()}}


def compare_stats(stats_a: dict[str, MotStats], stats_b: dict[str, MotStats], *,
                  resamples: int = 1000, seed: int = 0, level: str = "frames",
                  block: int | None = None,
                  method: str = "percentile") -> tuple[dict[str, dict[str, MetricDiff]], dict]:
    """Paired bootstrap of per-sequence statistics; returns ``(rows, block lengths)``."""
    if level not in ("frames", "sequences"):
        raise ValueError(f"level must be 'frames' or 'sequences', got {level!r}")
    rng = np.random.default_rng(seed)
    names = list(stats_a)
    rows: dict[str, dict[str, MetricDiff]] = {}
    parts_a, parts_b, points_a, points_b, blocks = [], [], [], [], {}
    for name in names:
        n = stats_a[name].num_frames
        blocks[name] = block_length(n) if block is None else min(int(block), n)
        w = block_weights(n, resamples, rng, blocks[name])
        ones = np.ones((1, n))
        sa, sb = weighted_sums(stats_a[name], w), weighted_sums(stats_b[name], w)
        pa, pb = weighted_sums(stats_a[name], ones), weighted_sums(stats_b[name], ones)
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
    return rows, blocks


#: Interval methods: percentile, basic (reflected) and bias-corrected percentile.
INTERVALS: tuple[str, ...] = ("percentile", "bc", "basic")


def interval(point: float, boot: np.ndarray, method: str = "percentile") -> tuple[float, float]:
    """The 95% interval of ``point`` from its bootstrap replicates ``boot``.

    ``percentile`` (the default) is the 2.5-97.5 percentile of the replicates; ``bc`` shifts
    them by the bootstrap's median bias (Efron's bias-corrected percentile) and ``basic``
    reflects them around ``point``. In the coverage simulation
    (``benchmarks/compare_coverage.py``) the plain percentiles covered best: the bias of the
    resampled IDF1/HOTA does not carry over to the estimate.
    """
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


def run_stats(run: str | os.PathLike, sequences: list[str]) -> dict[str, MotStats]:
    """Per-sequence statistics of a MOT run folder, from its result files and ground truth."""
    bench = run_benchmark(run)
    if bench.task != "mot":
        raise ValueError(f"{run}: `compare` supports box MOT runs; this run's task is "
                         f"'{bench.task}'")
    out = {}
    for name in sequences:
        frames = preprocessed_frames(read_gt_rows(bench.dataset.split_dir / name),
                                     bench.read(Path(run) / "data", name),
                                     bench.sequence_length(name), bench.name)
        out[name] = mot_stats(frames)
    return out


def compare_runs(run_a: str | os.PathLike, run_b: str | os.PathLike, *, resamples: int = 1000,
                 seed: int = 0, level: str = "frames", block: int | None = None) -> Comparison:
    """Compare two MOT run folders on the sequences both scored (see the module docstring)."""
    seq_a, seq_b = run_sequences(run_a), run_sequences(run_b)
    common = [s for s in seq_a if s in seq_b]
    if not common:
        raise ValueError(f"{run_a} and {run_b} have no scored sequence in common")
    stats_a, stats_b = run_stats(run_a, common), run_stats(run_b, common)
    rows, blocks = compare_stats(stats_a, stats_b, resamples=resamples, seed=seed, level=level,
                                 block=block)
    frames = {s: stats_a[s].num_frames for s in common}
    notes = few_data_notes(frames, blocks, level)
    for name in unreliable_rows(frames, blocks):
        for d in rows[name].values():
            d.reliable = False
    skipped = sorted(set(seq_a) ^ set(seq_b))
    if skipped:
        notes.append(f"not in both runs, left out: {', '.join(skipped)}")
    return Comparison(str(run_a), str(run_b), rows, frames, blocks, resamples, level, notes)


def _block_count(frames: dict[str, int], blocks: dict[str, int]) -> dict[str, int]:
    return {name: math.ceil(n / blocks[name]) for name, n in frames.items()}


def unreliable_rows(frames: dict[str, int], blocks: dict[str, int]) -> list[str]:
    """Rows whose interval rests on too few blocks.

    A sequence needs :data:`MIN_BLOCKS` blocks; the combined row needs one such sequence.
    """
    counts = _block_count(frames, blocks)
    out = [name for name, count in counts.items() if count < MIN_BLOCKS]
    return out + ([COMBINED] if len(out) == len(counts) else [])


def few_data_notes(frames: dict[str, int], blocks: dict[str, int], level: str) -> list[str]:
    """Plain warnings where too little data makes the intervals wide or unreliable."""
    notes = []
    counts = _block_count(frames, blocks)
    for name in unreliable_rows(frames, blocks):
        if name == COMBINED:
            notes.append(f"{COMBINED}: {sum(frames.values())} frames in all, no sequence with "
                         f"{MIN_BLOCKS} blocks: too little data for a trustworthy interval; do "
                         "not read a difference into it")
        else:
            notes.append(f"{name}: only {frames[name]} frames ({counts[name]} blocks of "
                         f"{blocks[name]}): too little data, its interval is not trustworthy "
                         "(so few blocks cannot show how much the difference varies)")
    if level == "sequences" and len(frames) < 10:
        notes.append(f"resampling {len(frames)} sequences: the sequence-level interval is "
                     "unstable with fewer than 10 sequences")
    return notes
