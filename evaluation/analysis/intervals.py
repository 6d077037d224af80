"""95% intervals of one run's combined metrics, and of every scorecard cell (``--ci``).

:mod:`~unitrack_env.evaluation.analysis.compare`'s delete-a-block jackknife with a t interval. The
run's benchmark says how (its ``intervals``): ``"stats"`` (box MOT) recomputes the metrics
from per-frame statistics; ``"frames"`` (SOT, VOS, JHMDB) takes the per-frame values of its
``frame_metrics`` from the events (means over frames), sequences combined as the official
score combines them (its ``combine_weights``); ``"counts"`` (TAP-Vid) recomputes each
sequence's metrics from per-frame additive counts and takes their mean over sequences; other
tasks (MOTS, PoseTrack, VIS) get none.
:func:`compare_runs` serves ``unitrack compare`` (and the report's comparison).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from unitrack_env.benchmarks.base import Benchmark
from unitrack_env.metrics.mot_stats import add_sums, metrics_from_sums, weighted_sums

from ..run.integrity import check_pair
from .compare import (
    COMBINED,
    Comparison,
    MetricDiff,
    block_length,
    compare_stats,
    few_data_notes,
    frame_block_length,
    jackknife_interval,
    jackknife_weights,
    run_stats,
    unreliable_rows,
)
from .events import load_events, run_benchmark, run_sequences


def _mot_intervals(run: Path) -> dict[str, tuple[float, float]]:
    stats = run_stats(run, run_sequences(run))
    point = [weighted_sums(s, np.ones((1, s.num_frames))) for s in stats.values()]
    total = add_sums(point)
    reps = []
    for s, p in zip(stats.values(), point, strict=True):
        left_out = weighted_sums(s, jackknife_weights(s.num_frames, block_length(s.num_frames)))
        reps.append({k: total[k] - p[k] + left_out[k] for k in total})
    values = metrics_from_sums(total)
    samples = metrics_from_sums({k: np.concatenate([r[k] for r in reps]) for k in total})
    return {m: jackknife_interval(float(values[m][0]), samples[m]) for m in values}


def frame_values(events: pd.DataFrame, bench: Benchmark,
                 sequences: list[str] | None = None) -> dict[str, dict[str, pd.Series]]:
    """``{sequence: {metric: per-frame values}}`` of a frame-scored run's ``"frame"`` events.

    One value per frame (the mean over a frame's objects) of each of the benchmark's
    ``frame_metrics``, indexed by frame number.
    """
    out = {}
    for name, seq in events.groupby("sequence", sort=False):
        if sequences is None or name in sequences:
            out[str(name)] = {
                metric: pd.Series(per_frame(seq), index=seq["frame"].to_numpy())
                .groupby(level=0).mean() for metric, per_frame in bench.frame_metrics.items()}
    return out


def frame_replicates(values: dict[str, np.ndarray], blocks: dict[str, int],
                     level: str = "frames", weights: dict[str, float] | None = None,
                     ) -> dict[str, tuple[float, np.ndarray]]:
    """Per sequence and ``COMBINED``: the mean over frames and its jackknife replicates.

    A sequence's replicates leave out one block of its frames each. ``COMBINED`` is the mean
    of the sequences' means with ``weights`` (the official combination: 1 per sequence for
    OTB, its objects for DAVIS), or with ``weights=None`` the mean of all frames pooled; its
    replicates leave out one block of one sequence at a time (``level="frames"``) or one
    whole sequence (``"sequences"``). NaN frames are skipped.
    """
    parts, out = {}, {}
    for name, v in values.items():
        keep = jackknife_weights(len(v), blocks[name])
        ok = np.isfinite(v)
        parts[name] = (keep[:, ok] @ v[ok], keep[:, ok].sum(1), v[ok].sum(), float(ok.sum()))
        out[name] = (parts[name][2] / max(parts[name][3], 1.0),
                     parts[name][0] / np.maximum(parts[name][1], 1))
    if weights is None:  # sums and counts of the pooled frames
        sums = {n: (p[2], p[0]) for n, p in parts.items()}
        counts = {n: (p[3], p[1]) for n, p in parts.items()}
    else:  # weighted sequence means: "sum" w * mean, "count" w
        sums = {n: (weights[n] * out[n][0], weights[n] * out[n][1]) for n in parts}
        counts = {n: (weights[n], np.full(len(out[n][1]), float(weights[n]))) for n in parts}
    total, n = sum(v[0] for v in sums.values()), sum(v[0] for v in counts.values())
    if level == "frames":
        rep_sums = np.concatenate([total - s[0] + s[1] for s in sums.values()])
        rep_counts = np.concatenate([n - c[0] + c[1] for c in counts.values()])
    else:
        rep_sums = np.array([total - s[0] for s in sums.values()])
        rep_counts = np.array([n - c[0] for c in counts.values()])
    out[COMBINED] = (total / max(n, 1e-12), rep_sums / np.maximum(rep_counts, 1e-12))
    return out


def _frame_intervals(run: Path, bench: Benchmark) -> dict[str, tuple[float, float]]:
    events = load_events(run, type="frame")
    by_seq = frame_values(events, bench)
    weights = bench.combine_weights(events, list(by_seq))
    out = {}
    for metric in bench.frame_metrics:
        values = {name: v[metric].to_numpy() for name, v in by_seq.items()}
        if any(np.isfinite(v).any() for v in values.values()):
            point, reps = frame_replicates(
                values, {name: frame_block_length(len(v)) for name, v in values.items()},
                weights=weights)[COMBINED]
            out[metric] = jackknife_interval(point, reps)
    return out


def compare_frames(run_a: str | os.PathLike, run_b: str | os.PathLike, bench: Benchmark,
                   sequences: list[str], *, level: str = "frames", block: int | None = None
                   ) -> tuple[dict[str, dict[str, MetricDiff]], dict[str, int], dict[str, int]]:
    """Paired jackknife rows of two frame-scored runs: ``(rows, frames, block lengths)``.

    Both runs' metrics are the means of the per-frame values of the benchmark's
    ``frame_metrics`` (recomputed from the events) over the frames both runs scored, combined
    as the official score combines sequences (its ``combine_weights``).
    """
    events_a = load_events(run_a, type="frame")
    va = frame_values(events_a, bench, sequences)
    vb = frame_values(load_events(run_b, type="frame"), bench, sequences)
    for run, values in ((run_a, va), (run_b, vb)):
        missing = [name for name in sequences if name not in values]
        if missing:
            raise ValueError(f"{run}: no per-frame events for {', '.join(missing)}")
    weights = bench.combine_weights(events_a, sequences)
    frames, blocks, rows = {}, {}, {}
    pairs = {}
    for name in sequences:
        first = next(iter(bench.frame_metrics))
        index = va[name][first].index.intersection(vb[name][first].index)
        frames[name] = len(index)
        blocks[name] = frame_block_length(len(index)) if block is None else max(
            1, min(int(block), len(index)))
        pairs[name] = index
    for metric in bench.frame_metrics:
        ra = frame_replicates({n: va[n][metric].loc[i].to_numpy() for n, i in pairs.items()},
                              blocks, level, weights)
        rb = frame_replicates({n: vb[n][metric].loc[i].to_numpy() for n, i in pairs.items()},
                              blocks, level, weights)
        for name in [*sequences, COMBINED]:
            (a, reps_a), (b, reps_b) = ra[name], rb[name]
            low, high = jackknife_interval(a - b, reps_a - reps_b)
            rows.setdefault(name, {})[metric] = MetricDiff(a, b, a - b, low, high)
    return rows, frames, blocks


def count_replicates(counts: dict[str, dict[str, np.ndarray]], blocks: dict[str, int],
                     bench: Benchmark, level: str = "frames",
                     ) -> dict[str, dict[str, tuple[float, np.ndarray]]]:
    """Per sequence and ``COMBINED``: ``{metric: (value, jackknife replicates)}``.

    ``counts``: per sequence the benchmark's per-frame additive counts (its
    :meth:`~unitrack_env.benchmarks.base.Benchmark.frame_counts`). A sequence's metrics are
    its ``metrics_of_counts`` of the counts summed over frames; each replicate sums them
    leaving out one block of frames. ``COMBINED`` is the mean over sequences of each metric
    where defined (NaN left out); its replicates swap one sequence's value for one of its
    replicates (``level="frames"``) or leave the whole sequence out (``"sequences"``).
    """
    out: dict[str, dict[str, tuple[float, np.ndarray]]] = {}
    for name, table in counts.items():
        keep = jackknife_weights(len(next(iter(table.values()))), blocks[name])
        sums = {key: keep @ np.asarray(v, np.float64) for key, v in table.items()}
        point = bench.metrics_of_counts({key: v.sum() for key, v in table.items()})
        reps = [bench.metrics_of_counts({key: s[j] for key, s in sums.items()})
                for j in range(len(keep))]
        out[name] = {m: (point[m], np.array([r[m] for r in reps], np.float64)) for m in point}
    names = list(counts)
    combined = {}
    for metric in out[names[0]] if names else ():
        values = np.array([out[n][metric][0] for n in names], np.float64)
        reps = []
        for i, name in enumerate(names):
            if level == "frames":
                for rep in out[name][metric][1]:
                    reps.append(_mean_defined(np.concatenate([values[:i], [rep],
                                                              values[i + 1:]])))
            else:
                reps.append(_mean_defined(np.delete(values, i)))
        combined[metric] = (_mean_defined(values), np.array(reps, np.float64))
    out[COMBINED] = combined
    return out


def _mean_defined(values: np.ndarray) -> float:
    """The mean of the values that are not NaN (NaN if none is)."""
    values = values[~np.isnan(values)]
    return float(values.mean()) if len(values) else float("nan")


def _run_counts(run: str | os.PathLike, bench: Benchmark,
                sequences: list[str]) -> dict[str, dict[str, np.ndarray]]:
    return {name: bench.frame_counts(Path(run) / "data", name) for name in sequences}


def _count_intervals(run: Path, bench: Benchmark) -> dict[str, tuple[float, float]]:
    counts = _run_counts(run, bench, run_sequences(run))
    blocks = {n: frame_block_length(len(next(iter(c.values())))) for n, c in counts.items()}
    return {metric: jackknife_interval(*pair) for metric, pair in
            count_replicates(counts, blocks, bench)[COMBINED].items()}


def compare_counts(run_a: str | os.PathLike, run_b: str | os.PathLike, bench: Benchmark,
                   sequences: list[str], *, level: str = "frames", block: int | None = None
                   ) -> tuple[dict[str, dict[str, MetricDiff]], dict[str, int], dict[str, int]]:
    """Paired jackknife rows of two runs scored from per-frame counts (``intervals="counts"``).

    Both runs' metrics are recomputed from the counts (:func:`count_replicates`); the same
    blocks of frames are left out of both. Returns ``(rows, frames, block lengths)``.
    """
    ca, cb = _run_counts(run_a, bench, sequences), _run_counts(run_b, bench, sequences)
    frames, blocks = {}, {}
    for name in sequences:
        frames[name] = len(next(iter(ca[name].values())))
        if len(next(iter(cb[name].values()))) != frames[name]:
            raise ValueError(f"{run_a} and {run_b} scored different frames of {name}")
        blocks[name] = frame_block_length(frames[name]) if block is None else max(
            1, min(int(block), frames[name]))
    ra, rb = (count_replicates(c, blocks, bench, level) for c in (ca, cb))
    rows: dict[str, dict[str, MetricDiff]] = {}
    for name in [*sequences, COMBINED]:
        for metric, (a, reps_a) in ra[name].items():
            b, reps_b = rb[name][metric]
            low, high = jackknife_interval(a - b, reps_a - reps_b)
            rows.setdefault(name, {})[metric] = MetricDiff(a, b, a - b, low, high)
    return rows, frames, blocks


def compare_runs(run_a: str | os.PathLike, run_b: str | os.PathLike, *, resamples: int = 1000,
                 seed: int = 0, level: str = "frames", block: int | None = None,
                 method: str = "jackknife") -> Comparison:
    """Compare two run folders on the sequences both scored (see the module docstring).

    The runs' benchmark says how (its ``intervals``): ``"stats"`` (box MOT) recomputes the
    metrics from per-frame statistics; ``"frames"`` (SOT, VOS, JHMDB) compares per-frame
    metrics (:func:`compare_frames`, jackknife only); ``"counts"`` recomputes per-sequence
    metrics from per-frame counts (:func:`compare_counts`, jackknife only); otherwise it
    refuses with the
    benchmark's ``no_intervals``. Both runs' result files must still match their records and
    their data must be the same (:func:`~.integrity.check_pair`: StaleRun / DifferentData
    otherwise).
    """
    bench = _common_benchmark(run_a, run_b)
    seq_a, seq_b = run_sequences(run_a), run_sequences(run_b)
    common = [s for s in seq_a if s in seq_b]
    if not common:
        raise ValueError(f"{run_a} and {run_b} have no scored sequence in common")
    check_pair(run_a, run_benchmark(run_a), run_b, run_benchmark(run_b), common)
    pooled = bench.intervals in ("frames", "counts")
    if not pooled:
        stats_a, stats_b = run_stats(run_a, common), run_stats(run_b, common)
        options = dict(resamples=resamples, seed=seed, level=level, block=block, method=method)
        rows, blocks = compare_stats(stats_a, stats_b, **options)
        for cls in bench.stat_classes():  # classes scored one by one: their rows too
            by_class, _ = compare_stats(run_stats(run_a, common, cls),
                                        run_stats(run_b, common, cls), **options)
            for row, diffs in by_class.items():
                rows[row].update({f"{cls}/{name}": diff for name, diff in diffs.items()})
        frames = {s: stats_a[s].num_frames for s in common}
    else:
        if level not in ("frames", "sequences"):
            raise ValueError(f"level must be 'frames' or 'sequences', got {level!r}")
        if method != "jackknife":
            raise ValueError(f"--interval {method} is for box MOT runs; {bench.task} runs are "
                             "compared with the block jackknife")
        compare = compare_frames if bench.intervals == "frames" else compare_counts
        rows, frames, blocks = compare(run_a, run_b, bench, common, level=level, block=block)
    notes = few_data_notes(frames, blocks, level, pooled=pooled)
    for name in unreliable_rows(frames, blocks, pooled=pooled):
        for d in rows[name].values():
            d.reliable = False
    skipped = sorted(set(seq_a) ^ set(seq_b))
    if skipped:
        notes.append(f"not in both runs, left out: {', '.join(skipped)}")
    return Comparison(str(run_a), str(run_b), rows, frames, blocks, resamples, level, notes,
                      method)


def comparable(bench: Benchmark) -> bool:
    """Whether ``compare`` can compare runs of ``bench`` (its ``intervals`` are stated)."""
    return bench.intervals in ("stats", "frames", "counts")


def _common_benchmark(run_a: str | os.PathLike, run_b: str | os.PathLike) -> Benchmark:
    benches = [run_benchmark(r) for r in (run_a, run_b)]
    tasks = [b.task for b in benches]
    if tasks[0] != tasks[1]:
        raise ValueError(f"{run_a} is a {tasks[0]} run and {run_b} a {tasks[1]} run: "
                         "compare two runs of the same task")
    if not comparable(benches[0]):
        raise ValueError(f"{run_a}: `compare` cannot compare {tasks[0]} runs: "
                         f"{benches[0].no_intervals}")
    return benches[0]


def run_intervals(run: str | os.PathLike, *, resamples: int = 1000,
                  seed: int = 0) -> dict[str, tuple[float, float]]:
    """``{metric: (low, high)}``: 95% intervals of a run folder's combined metrics.

    ``resamples`` and ``seed`` are accepted for callers but unused: the jackknife is exact.
    """
    del resamples, seed
    run = Path(run)
    bench = run_benchmark(run)
    if bench.intervals == "stats":
        return _mot_intervals(run)
    if bench.intervals == "frames":
        return _frame_intervals(run, bench)
    if bench.intervals == "counts":
        return _count_intervals(run, bench)
    return {}
