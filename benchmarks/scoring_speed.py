"""Scoring speed: TrackEval (official scorer) vs py-motmetrics (cross-check) on one sequence.

Plays the `iou` baseline on the real PETS09-S2L1 (400 frames, MOT15 layout), then times
scoring its results with each library and prints both times, their ratio and the metrics
they agree on.

Usage: python benchmarks/scoring_speed.py [--mot15 ../shared/data/MOT15] [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from unitrack_env.datasets.motchallenge import read_seqinfo
from unitrack_env.evaluation.analysis.crosscheck import motmetrics_summary
from unitrack_env.evaluation.run.runner import run
from unitrack_env.metrics.mot_preprocess import gt_frames_from_rows, tracker_frames_from_rows
from unitrack_env.metrics.mot_results import read_result_file
from unitrack_env.metrics.motchallenge import score_sequence

REPO = Path(__file__).resolve().parents[1]


def timed(fn, repeats: int):
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--mot15", type=Path, default=REPO / ".." / "shared" / "data" / "MOT15")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    seq_dir = args.mot15 / "train" / "PETS09-S2L1"
    if not seq_dir.is_dir():
        raise SystemExit(f"{seq_dir} not found")
    with tempfile.TemporaryDirectory() as out:
        run("UniTrack/MOT15-v0", "iou", out=out, progress=False,
            env_kwargs={"root": str(args.mot15), "decode_frames": False})
        results = read_result_file(Path(out) / "data" / "PETS09-S2L1.txt")
    length = read_seqinfo(seq_dir).length
    gt_rows = np.loadtxt(seq_dir / "gt" / "gt.txt", delimiter=",")

    score_sequence(seq_dir, results, benchmark="MOT15")  # import + warm-up
    te_time, te = timed(lambda: score_sequence(seq_dir, results, benchmark="MOT15"), args.repeats)

    def with_motmetrics():
        gt = gt_frames_from_rows(gt_rows, length, benchmark="MOT15")
        trk = tracker_frames_from_rows(results, length)
        return motmetrics_summary(gt, trk, benchmark="MOT15")

    with_motmetrics()
    mm_time, mm = timed(with_motmetrics, args.repeats)
    print(f"PETS09-S2L1, {length} frames, {len(results)} tracker boxes, {len(gt_rows)} gt rows")
    print(f"TrackEval (HOTA + CLEAR + Identity): {te_time * 1e3:.1f} ms")
    print(f"py-motmetrics (CLEAR + ID measures): {mm_time * 1e3:.1f} ms")
    print(f"ratio motmetrics / TrackEval: {mm_time / te_time:.2f}")
    for key in ("MOTA", "IDF1", "IDSW", "CLR_FP", "CLR_FN"):
        print(f"  {key:6s} TrackEval {te[key]:.6f}   motmetrics {mm[key]:.6f}")
    if any(abs(te[k] - mm[k]) > 1e-9 for k in ("MOTA", "IDF1", "IDSW")):
        print("  (the libraries match differently after a gap and in crowded overlaps; see the "
              "unitrack_env.evaluation.analysis.crosscheck docstring. TrackEval is the official "
              "scorer.)")


if __name__ == "__main__":
    main()
