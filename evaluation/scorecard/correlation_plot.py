"""The correlation study's figure (the UniTrack paper's Figure 4).

The report draws its section from the same files
(:func:`unitrack_env.evaluation.report.build.correlation_section`).

One figure per external metric: a scatter panel per task, the other evaluation on the x-axis,
tracking on the y-axis, each model's label beside its point, and both coefficients in the
panel's lower left corner as in the paper. PNG and SVG with the same bytes for the same
study (no date, a fixed SVG id salt).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..plots.figures import pyplot, save_figure


def _coefficients(row: dict[str, Any]) -> str:
    if row["pearson"] is None:
        return f"n={row['n']}: no coefficient"
    return (f"ρ = {row['spearman']:+.2f}\nr = {row['pearson']:+.2f}\n"
            f"n = {row['n']}")


def draw_scatter(rows: list[dict[str, Any]], stem: Path) -> list[Path]:
    """Write ``<stem>.png`` and ``<stem>.svg`` for one metric's rows; [] without matplotlib."""
    plt = pyplot("correlation figure")
    if plt is None:
        return []
    figure, panels = plt.subplots(1, len(rows), figsize=(3.0 * len(rows), 3.2), squeeze=False)
    for ax, row in zip(panels[0], rows, strict=True):
        xs = [p["x"] for p in row["scatter"]]
        ys = [100 * p["y"] for p in row["scatter"]]
        hollow = row["source"] == "synthetic"
        ax.scatter(xs, ys, s=22, color="tab:blue", facecolors="white" if hollow else None)
        for point, x, y in zip(row["scatter"], xs, ys, strict=True):
            ax.annotate(point["model"], (x, y), fontsize=6, xytext=(3, 2),
                        textcoords="offset points")
        ax.text(0.03, 0.03, _coefficients(row), transform=ax.transAxes, fontsize=8,
                va="bottom", ha="left", bbox={"facecolor": "white", "alpha": 0.8,
                                              "edgecolor": "none"})
        synthetic = "\n[synthetic data]" if hollow else ""
        ax.set_title(row["title"] + synthetic, fontsize=9)
        ax.set_xlabel(row["metric_name"] + (" (lower is better)" if row["lower_is_better"]
                                            else ""), fontsize=8)
        ax.tick_params(labelsize=7)
    panels[0][0].set_ylabel("tracking (%)", fontsize=8)
    figure.tight_layout()
    stem.parent.mkdir(parents=True, exist_ok=True)
    return save_figure(figure, stem, "unitrack-correlation", dpi=150, tight=False)


def figure_stem(name: str) -> str:
    """A file-name-safe form of a metric name (``probe:imagenet`` -> ``probe-imagenet``)."""
    return "".join(ch if ch.isalnum() or ch in "-_." else "-" for ch in name)
