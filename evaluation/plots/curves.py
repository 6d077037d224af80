"""Success and precision plots of run folders on one figure each, as PNG and SVG.

Each run's benchmark gives its curves (:meth:`~unitrack_env.benchmarks.base.Benchmark.curves`)
from the run's result files and ground truth; the legend shows the score of each run (AUC,
precision at 20 px). Same bytes for the same runs: no date, a fixed SVG salt.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from ..analysis.events import run_benchmark, run_sequences
from .figures import pyplot, save_figure


def run_curves(run: Path) -> tuple[str, list[Any]]:
    """``(legend label, curves)`` of one run folder ([] when its benchmark has no plots)."""
    bench = run_benchmark(run)
    spec = json.loads((run / "run.json").read_text(encoding="utf-8"))
    label = f"{run.name} ({spec.get('agent', '?')})"
    return label, bench.curves(run / "data", run_sequences(run))


def plot_stem(title: str) -> str:
    """File stem of a plot: ``"Success plot"`` -> ``"success-plot"``."""
    return re.sub(r"[^a-z0-9]+", "-", title.lower()).strip("-")


def draw_curves(runs: list[Path], out: Path, *, prefix: str = "") -> list[Path]:
    """Write ``out/<prefix><plot>.png`` and ``.svg`` per plot of the runs; return the files.

    Raises ValueError when no run's benchmark has such plots; [] without matplotlib.
    """
    labelled = [run_curves(run) for run in runs]
    if not any(curves for _, curves in labelled):
        raise ValueError(f"no success or precision plots for {', '.join(map(str, runs))}: "
                         "their benchmarks draw none (only SOT runs have them)")
    return draw_labelled(labelled, out, prefix=prefix)


def draw_labelled(labelled: list[tuple[str, list[Any]]], out: Path, *,
                  prefix: str = "") -> list[Path]:
    """Draw ``(legend label, curves)`` of runs: one figure per plot title, PNG then SVG."""
    titles: list[str] = []
    for _, curves in labelled:
        titles += [c.title for c in curves if c.title not in titles]
    plt = pyplot("plots")
    if plt is None:
        return []
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for title in titles:
        lines = [(label, c) for label, curves in labelled for c in curves if c.title == title]
        written += save_figure(_figure(plt, title, lines), out / f"{prefix}{plot_stem(title)}",
                               "unitrack-curves")
    return written


def _figure(plt: Any, title: str, lines: list[tuple[str, Any]]) -> Any:
    figure, ax = plt.subplots(figsize=(5.5, 4.2))
    # the best score first in the legend, as the toolkits order it
    for label, curve in sorted(lines, key=lambda item: -item[1].score[1]):
        metric, value = curve.score
        ax.plot(curve.x, curve.y, linewidth=1.8, label=f"{label} [{metric} {100 * value:.1f}]")
    ax.set_title(title)
    ax.set_xlabel(lines[0][1].x_label)
    ax.set_ylabel("Fraction of frames")
    ax.set_ylim(0, 1.02)
    ax.set_xlim(min(lines[0][1].x), max(lines[0][1].x))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower left" if title.startswith("Success") else "lower right",
              fontsize=8)
    return figure


__all__ = ["draw_curves", "draw_labelled", "plot_stem", "run_curves"]
