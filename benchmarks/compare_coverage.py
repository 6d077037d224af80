"""Coverage of `unitrack compare`'s 95% intervals, by simulation with a known true difference.

Synthetic scenes come from one stationary process: pedestrians are born (Poisson), walk
(random walk) and leave (geometric lifetimes); two simulated trackers A and B watch the same
scene (paired) and differ in their miss rate (misses come in bursts: a two-state Markov
chain), their ID-switch rate, their false positives and their box jitter. The true difference
of each metric is the mean difference over ``--truth`` independent data sets of the same size;
then ``--reps`` fresh data sets each get a paired interval per method and block length
(:func:`unitrack_env.evaluation.analysis.compare.compare_stats`: the block jackknife, or the block
bootstrap's percentile/bc/basic intervals), and the script prints how often the interval holds
the true difference (it should be close to 95%), with the mean width.

    python benchmarks/compare_coverage.py --reps 100 --truth 100 \
        --intervals jackknife,percentile --blocks auto,40                  # docs/report.md
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass

import numpy as np
from scipy.stats import t as STUDENT

from unitrack_env.evaluation.analysis.compare import COMBINED, block_length, compare_stats
from unitrack_env.metrics.events_mot import preprocessed_frames
from unitrack_env.metrics.mot_stats import (
    MOT_STAT_METRICS,
    MotStats,
    add_sums,
    metrics_from_sums,
    mot_stats,
    weighted_sums,
)


@dataclass(frozen=True)
class TrackerModel:
    """How a simulated tracker errs."""

    miss_start: float  # P(hit -> miss) per object and frame
    miss_stop: float  # P(miss -> hit)
    switch: float  # P(the object's track gets a new id) per frame
    false_pos: float  # mean false positives per frame
    jitter: float  # box noise, pixels


A = TrackerModel(miss_start=0.04, miss_stop=0.25, switch=0.008, false_pos=0.4, jitter=4.0)
B = TrackerModel(miss_start=0.06, miss_stop=0.25, switch=0.014, false_pos=0.5, jitter=4.5)


def scene(frames: int, rng: np.random.Generator) -> np.ndarray:
    """Ground-truth rows ``frame, id, x, y, w, h, 1, -1, -1, -1`` of one scene."""
    rows, alive, next_id = [], {}, 1
    for _ in range(5):  # start populated
        alive[next_id] = rng.uniform([0, 0], [700, 450])
        next_id += 1
    for t in range(1, frames + 1):
        for _ in range(rng.poisson(0.08)):
            alive[next_id] = rng.uniform([0, 0], [700, 450])
            next_id += 1
        for g in list(alive):
            if rng.random() < 1 / 80:
                del alive[g]
                continue
            alive[g] = alive[g] + rng.normal(0, 3, 2)
            x, y = alive[g]
            rows.append([t, g, x, y, 40, 100, 1, -1, -1, -1])
    return np.array(rows, dtype=np.float64)


def track(gt: np.ndarray, frames: int, model: TrackerModel,
          rng: np.random.Generator) -> np.ndarray:
    """A simulated tracker's result rows on a scene."""
    out, missing, track_of, next_id = [], {}, {}, 10_000
    for t in range(1, frames + 1):
        for row in gt[gt[:, 0] == t]:
            g = int(row[1])
            if g not in track_of or rng.random() < model.switch:
                track_of[g], next_id = next_id, next_id + 1
            p = model.miss_stop if missing.get(g) else 1 - model.miss_start
            missing[g] = rng.random() >= p
            if missing[g]:
                continue
            x, y = row[2:4] + rng.normal(0, model.jitter, 2)
            out.append([t, track_of[g], x, y, 40, 100, 1, -1, -1, -1])
        for _ in range(rng.poisson(model.false_pos)):
            out.append([t, next_id, *rng.uniform([0, 0], [700, 450]), 40, 100, 1, -1, -1, -1])
            next_id += 1
    return np.array(out, dtype=np.float64).reshape(-1, 10)


def dataset(sequences: int, frames: int,
            rng: np.random.Generator) -> tuple[dict[str, MotStats], dict[str, MotStats]]:
    """Per-sequence statistics of trackers A and B on fresh scenes."""
    sa, sb = {}, {}
    for s in range(sequences):
        gt = scene(frames, rng)
        for model, out in ((A, sa), (B, sb)):
            rows = track(gt, frames, model, rng)
            out[f"seq{s}"] = mot_stats(preprocessed_frames(gt, rows, frames, "MOT15"))
    return sa, sb


def point_diff(sa: dict[str, MotStats], sb: dict[str, MotStats]) -> dict[str, float]:
    """Combined metric differences A - B of one data set."""
    def combined(stats: dict[str, MotStats]) -> dict[str, np.ndarray]:
        return metrics_from_sums(add_sums([weighted_sums(s, np.ones((1, s.num_frames)))
                                           for s in stats.values()]))
    ma, mb = combined(sa), combined(sb)
    return {m: float(ma[m][0] - mb[m][0]) for m in MOT_STAT_METRICS}


def main() -> None:
    """Measure and print the coverage."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=50, help="data sets with an interval")
    ap.add_argument("--truth", type=int, default=50, help="data sets for the true difference")
    ap.add_argument("--sequences", type=int, default=2, help="sequences per data set")
    ap.add_argument("--frames", type=int, default=400, help="frames per sequence")
    ap.add_argument("--resamples", type=int, default=200, help="bootstrap resamples")
    ap.add_argument("--seed", type=int, default=2, help="random seed")
    ap.add_argument("--intervals", default="jackknife", help="comma-separated interval "
                    "methods (jackknife, percentile, bc, basic) measured side by side")
    ap.add_argument("--blocks", default="auto", help="comma-separated block lengths to "
                    "measure side by side on the same data sets (auto: the default rule)")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    start = time.perf_counter()
    truth_runs = [point_diff(*dataset(args.sequences, args.frames, rng))
                  for _ in range(args.truth)]
    truth = {m: float(np.mean([d[m] for d in truth_runs])) for m in MOT_STAT_METRICS}
    spread = {m: float(np.std([d[m] for d in truth_runs], ddof=1)) for m in MOT_STAT_METRICS}
    blocks = [None if b == "auto" else int(b) for b in args.blocks.split(",")]
    methods = args.intervals.split(",")
    hits = {(b, i, m): 0 for b in blocks for i in methods for m in MOT_STAT_METRICS}
    widths: dict[tuple, list[float]] = {k: [] for k in hits}
    for rep in range(args.reps):
        sa, sb = dataset(args.sequences, args.frames, rng)
        for b in blocks:
            for i in methods:
                rows, _ = compare_stats(sa, sb, resamples=args.resamples, seed=rep, block=b,
                                        method=i)
                for m, d in rows[COMBINED].items():
                    hits[b, i, m] += d.low <= truth[m] <= d.high
                    widths[b, i, m].append(d.high - d.low)
    print(f"{args.reps} data sets of {args.sequences} x {args.frames} frames, "
          f"{args.resamples} bootstrap resamples where bootstrapped; true difference from "
          f"{args.truth} more data sets ({time.perf_counter() - start:.0f} s)")
    report(args, truth, spread, hits, widths)


def report(args: argparse.Namespace, truth: dict, spread: dict, hits: dict,
           widths: dict) -> None:
    """Print the coverage table; ``SE / SD`` is the interval's implied standard error
    (half-width over its quantile: 1.96, or t(k - 1) for the jackknife of k blocks) over the
    true spread of the estimate across data sets."""
    print(f"{'block':<6} {'interval':<10} {'metric':<6} {'true A-B':>9} {'coverage':>9} "
          f"{'mean width':>11} {'4 x SD of A-B':>14} {'SE / SD':>8}")
    for b, i, m in hits:
        ell = b or block_length(args.frames)
        k = args.sequences * math.ceil(args.frames / ell)
        q = float(STUDENT.ppf(0.975, k - 1)) if i == "jackknife" else 1.96
        width = float(np.mean(widths[b, i, m]))
        print(f"{ell:<6} {i:<10} {m:<6} "
              f"{100 * truth[m]:>+9.2f} {100 * hits[b, i, m] / args.reps:>8.1f}% "
              f"{100 * width:>10.2f} {400 * spread[m]:>14.2f} {width / 2 / q / spread[m]:>8.2f}")
    print(f"(a coverage within ±{100 * 1.96 * np.sqrt(0.95 * 0.05 / args.reps):.1f} points "
          f"of 95% is consistent with 95% at {args.reps} data sets)")


if __name__ == "__main__":
    main()
