"""95% intervals of one run's combined metrics, and of every scorecard cell (``--ci``).

The method is :mod:`~unitrack_env.evaluation.compare`'s: a delete-a-block jackknife over
blocks of frames (a fifth of each sequence), with a t interval. Box MOT recomputes HOTA, DetA,
AssA, IDF1 and MOTA from the per-frame statistics (:mod:`unitrack_env.metrics.mot_stats`).
Tasks scored per frame use their events: SOT's AUC (each frame's share of the success
curve) and Precision@20px, VOS's J-Mean, F-Mean and J&F-Mean (means over frames and objects),
pose propagation's PCK@0.1 (the mean of per-frame PCK, which weights frames equally where the
official score pools joints). Other tasks (MOTS, PoseTrack, VIS) get no interval.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from unitrack_env.metrics.mot_stats import add_sums, metrics_from_sums, weighted_sums

from .compare import block_length, jackknife_interval, jackknife_weights, run_stats
from .events import load_events, run_benchmark, run_sequences

#: Per-frame value of each interval metric of a frame-scored task.
FRAME_METRICS: dict[str, dict[str, Any]] = {
    "sot": {"AUC": lambda d: np.mean(d["iou"].to_numpy()[:, None]
                                     > np.linspace(0, 1, 21)[None, :], axis=1),
            "Precision@20px": lambda d: (d["center_error"] <= 20).to_numpy(float)},
    "vos": {"J-Mean": lambda d: d["j"].to_numpy(), "F-Mean": lambda d: d["f"].to_numpy(),
            "J&F-Mean": lambda d: (d["j"].to_numpy() + d["f"].to_numpy()) / 2},
    "pose-prop": {"PCK@0.1": lambda d: d["pck"].to_numpy()},
}


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


def _frame_intervals(run: Path, task: str) -> dict[str, tuple[float, float]]:
    events = load_events(run, type="frame")
    out = {}
    for metric, per_frame in FRAME_METRICS[task].items():
        parts = []  # (per-block sums, per-block counts) of each sequence
        for _, seq in events.groupby("sequence"):
            # one value per frame (the mean over a frame's objects)
            frame_values = pd.Series(per_frame(seq), index=seq["frame"].to_numpy())
            values = frame_values.groupby(level=0).mean().to_numpy()
            keep = jackknife_weights(len(values), block_length(len(values)))
            ok = np.isfinite(values)
            parts.append((keep[:, ok] @ values[ok], keep[:, ok].sum(1),
                          values[ok].sum(), float(ok.sum())))
        total, n = sum(p[2] for p in parts), sum(p[3] for p in parts)
        if n:
            sums = np.concatenate([total - p[2] + p[0] for p in parts])
            counts = np.concatenate([n - p[3] + p[1] for p in parts])
            out[metric] = jackknife_interval(total / n, sums / np.maximum(counts, 1))
    return out


def run_intervals(run: str | os.PathLike, *, resamples: int = 1000,
                  seed: int = 0) -> dict[str, tuple[float, float]]:
    """``{metric: (low, high)}``: 95% intervals of a run folder's combined metrics.

    ``resamples`` and ``seed`` are accepted for callers but unused: the jackknife is exact.
    """
    del resamples, seed
    run = Path(run)
    task = run_benchmark(run).task
    if task == "mot":
        return _mot_intervals(run)
    if task in FRAME_METRICS:
        return _frame_intervals(run, task)
    return {}


def card_intervals(out: str | os.PathLike, card: dict[str, Any], *,
                   resamples: int = 1000) -> dict[tuple[str, str, str], dict]:
    """Intervals of every (model, task, head) row of a scorecard made in ``out``."""
    from .scorecard import Cell

    result = {}
    for row in card["rows"]:
        folder = Path(out) / "cells" / Cell(row["model"], row["task"], row["head"], "", "",
                                            "").folder
        if (folder / "metrics.json").is_file():
            result[row["model"], row["task"], row["head"]] = run_intervals(
                folder, resamples=resamples)
    return result


def write_card_intervals(out: str | os.PathLike, card: dict[str, Any], *,
                         resamples: int = 1000) -> list[Path]:
    """``scorecard_ci.md`` and ``scorecard_ci.json``: each cell's value with its interval."""
    from .scorecard import BASELINE, TASKS
    from .scorecard_report import columns, value

    found = card_intervals(out, card, resamples=resamples)
    lines = ["| model | task | head | metric | value | 95% interval |", "|---|---|---|---|---|---|"]
    payload = []
    for model in [*card["models"], BASELINE]:
        for task, head, metric in columns(card):
            number = value(card, model, task, head, metric)
            if number is None:
                continue
            row_head = TASKS[task].baseline.label if model == BASELINE else head
            ci = found.get((model, task, row_head), {}).get(metric)
            text = f"[{100 * ci[0]:.1f}, {100 * ci[1]:.1f}]" if ci else "-"
            lines.append(f"| {model} | {task} | {row_head} | {metric} | {100 * number:.1f} | "
                         f"{text} |")
            payload.append({"model": model, "task": task, "head": row_head, "metric": metric,
                            "value": number, "low": ci[0] if ci else None,
                            "high": ci[1] if ci else None})
    lines += ["", "Delete-a-block jackknife over frames (blocks of a fifth of each sequence, "
              "t 95% intervals); see docs/report.md."]
    paths = [Path(out) / "scorecard_ci.md", Path(out) / "scorecard_ci.json"]
    paths[0].write_text("\n".join(lines) + "\n", encoding="utf-8")
    paths[1].write_text(json.dumps(payload, indent=2), encoding="utf-8")
    return paths
