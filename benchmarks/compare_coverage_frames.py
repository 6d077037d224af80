"""Coverage of `unitrack compare`'s 95% intervals for frame-scored tasks (SOT, VOS, JHMDB).

Two simulated single-object trackers A and B follow the same targets (paired). Each run's
per-frame IoU is 0 while it has lost the target and a Beta-distributed overlap otherwise;
losing and re-finding the target are a two-state Markov chain per tracker, and a shared
per-frame difficulty (an AR(1) process) lowers both runs' overlaps together, so the frames
of a sequence are correlated within and across runs. The metric is SOT's AUC (each frame's
share of the success curve), combined over sequences with equal weights as OTB does.

The true difference is the mean difference over ``--truth`` data sets; ``--reps`` fresh data
sets each get the interval of :func:`unitrack_env.evaluation.analysis.intervals.frame_replicates`
(the code ``unitrack compare`` runs) and the script prints how often it holds the true
difference, with its mean width, per number of sequences and frames.

    python benchmarks/compare_coverage_frames.py --reps 400 --truth 400 \
        --designs 1x400,3x200,5x100,20x100 [--block -1]                    # docs/report.md
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from unitrack_env.evaluation.analysis.compare import (
    COMBINED,
    block_length,
    frame_block_length,
    jackknife_interval,
)
from unitrack_env.evaluation.analysis.intervals import frame_replicates

THRESHOLDS = np.linspace(0, 1, 21)


def lost_chain(rng: np.random.Generator, frames: int, p_lose: float, p_find: float) -> np.ndarray:
    """Bool per frame: the tracker has lost the target (starts tracked)."""
    lost = np.zeros(frames, dtype=bool)
    for t in range(1, frames):
        lost[t] = rng.random() < (1 - p_find if lost[t - 1] else p_lose)
    return lost


def sequence(rng: np.random.Generator, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame AUC shares of runs A and B on one simulated sequence."""
    difficulty = np.zeros(frames)
    for t in range(1, frames):
        difficulty[t] = 0.95 * difficulty[t - 1] + rng.normal(0, 0.1)
    out = []
    for p_lose, p_find, mean in ((0.01, 0.05, 0.72), (0.015, 0.05, 0.68)):
        iou = rng.beta(8 * mean, 8 * (1 - mean), frames) * np.clip(1 - np.abs(difficulty), 0, 1)
        iou[lost_chain(rng, frames, p_lose, p_find)] = 0.0
        out.append((iou[:, None] > THRESHOLDS[None, :]).mean(axis=1))
    return out[0], out[1]


def data_set(rng: np.random.Generator, sequences: int, frames: int):
    pairs = [sequence(rng, frames) for _ in range(sequences)]
    return ({f"s{i}": a for i, (a, _) in enumerate(pairs)},
            {f"s{i}": b for i, (_, b) in enumerate(pairs)})


def combined_diff(a: dict, b: dict, level: str = "frames",
                  block: int | None = None) -> tuple[float, tuple[float, float]]:
    rule = frame_block_length if block == 0 else block_length
    blocks = {n: block or rule(len(v)) for n, v in a.items()}
    weights = dict.fromkeys(a, 1.0)
    (pa, ra), (pb, rb) = (frame_replicates(x, blocks, level, weights)[COMBINED] for x in (a, b))
    return pa - pb, jackknife_interval(pa - pb, ra - rb)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=200)
    parser.add_argument("--truth", type=int, default=200)
    parser.add_argument("--designs", default="1x400,3x200,5x100",
                        help="SEQUENCESxFRAMES, comma-separated")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--level", choices=("frames", "sequences"), default="frames")
    parser.add_argument("--block", type=int, default=0,
                        help="block length; 0 (default): `compare`'s rule, a fifth of the "
                        "sequence but at least 50 frames; -1: a fifth")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    start = time.perf_counter()
    print(f"{args.reps} data sets per design; true difference from {args.truth} more; "
          f"level {args.level}, blocks: "
          f"{ {0: 'a fifth, at least 50 frames', -1: 'a fifth'}.get(args.block, args.block)}")
    print(f"{'design':<8} {'true A-B':>9} {'coverage':>9} {'mean width':>11} {'4 x SD':>8}")
    for design in args.designs.split(","):
        s, f = (int(x) for x in design.split("x"))
        truth = np.mean([combined_diff(*data_set(rng, s, f))[0] for _ in range(args.truth)])
        diffs, hits, widths = [], 0, []
        for _ in range(args.reps):
            d, (low, high) = combined_diff(*data_set(rng, s, f), args.level,
                                           None if args.block == -1 else args.block)
            diffs.append(d)
            hits += low <= truth <= high
            widths.append(high - low)
        print(f"{design:<8} {100 * truth:+9.2f} {100 * hits / args.reps:8.1f}% "
              f"{100 * np.mean(widths):11.2f} {400 * np.std(diffs):8.2f}")
    half = 1.96 * math.sqrt(0.95 * 0.05 / args.reps)
    print(f"(a coverage within ±{100 * half:.1f} points of 95% is consistent with 95% at "
          f"{args.reps} data sets; {time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
