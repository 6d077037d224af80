"""A scorecard's cells with their 95% intervals: ``scorecard_ci.md`` and ``scorecard_ci.json``.

Each cell is a run folder, and its interval the run's own
(:func:`unitrack_env.evaluation.analysis.intervals.run_intervals`: a delete-a-block jackknife
over frames, or over counts where the task's metrics are sums).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from unitrack_env.io import atomic_write_text

from ..analysis.intervals import run_intervals
from .plan import BASELINE, TASKS, Cell
from .table import columns, value


def card_intervals(out: str | os.PathLike, card: dict[str, Any], *,
                   resamples: int = 1000) -> dict[tuple[str, str, str], dict]:
    """Intervals of every (model, task, head) row of a scorecard made in ``out``."""
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
    atomic_write_text(paths[0], "\n".join(lines) + "\n")  # never through a link
    atomic_write_text(paths[1], json.dumps(payload, indent=2))
    return paths
