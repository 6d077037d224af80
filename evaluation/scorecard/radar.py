"""The radar chart of a scorecard (the UniTrack paper's Figure 1), as PNG and SVG.

The ``rank`` scale is the paper's ("A higher rank (better performance) corresponds to a vertex
nearer to the outer circle"): on each axis the best polygon lies at radius 1, the worst at 1/n,
ties share a rank; ``value`` draws the metric (a fraction). The baselines are a grey dashed
polygon, as the paper draws its reference model; axes on synthetic data say so and get hollow
vertices, so that nobody reads them as benchmark numbers. Under three tasks: grouped bars.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ..plots.figures import pyplot, save_figure
from .plan import BASELINE, TASKS
from .table import polygon_values

#: Label suffix per data source.
SOURCE_NOTES = {"benchmark": "", "fixture": "\n(fixture)", "synthetic": "\n[synthetic data]"}


def axes(card: dict[str, Any]) -> list[tuple[str, str, str, str]]:
    """(task, head, metric, label) of every radar axis."""
    out = []
    for task in card["tasks"]:
        spec = TASKS[task]
        head, metric = spec.axis
        several = len(spec.heads) > 1
        name = f"{metric} ({head})" if several else metric
        label = f"{spec.title}\n{name}{SOURCE_NOTES[card['sources'][task]['kind']]}"
        out.append((task, head, metric, label))
    return out


def radii(card: dict[str, Any], scale: str = "rank") -> dict[str, list[float | None]]:
    """Each polygon's radius on each axis (None: no value)."""
    values = polygon_values(card, axes(card))
    if scale == "value":
        return values
    if scale != "rank":
        raise ValueError(f"radar scale must be 'rank' or 'value', not '{scale}'")
    names = list(values)
    out: dict[str, list[float | None]] = {name: [] for name in names}
    for i in range(len(axes(card))):
        column = {n: values[n][i] for n in names if values[n][i] is not None}
        for name in names:
            mine = values[name][i]
            if mine is None:
                out[name].append(None)
                continue
            rank = 1 + sum(other > mine for other in column.values())
            out[name].append(1 - (rank - 1) / len(names))
    return out


def draw_radar(card: dict[str, Any], stem: Path, *, scale: str = "rank") -> list[Path]:
    """Write ``<stem>.png`` and ``<stem>.svg``; return the files written ([] without matplotlib)."""
    plt = pyplot("radar chart")
    if plt is None:
        return []
    spokes = axes(card)
    data = radii(card, scale)
    draw = _polygons if len(spokes) >= 3 else _bars
    figure = draw(plt, card, spokes, data, scale)
    stem.parent.mkdir(parents=True, exist_ok=True)
    # No date and a fixed salt for the SVG's element ids: the same card draws the same bytes,
    # so scoring a committed scorecard again leaves its charts untouched
    return save_figure(figure, stem, "unitrack-radar", dpi=150)


def _style(plt: Any, name: str, index: int) -> dict[str, Any]:
    """Line style of one polygon: the baselines grey and dashed, the models in tab10."""
    if name == BASELINE:
        return {"color": "0.5", "linestyle": "--", "linewidth": 1.2}
    return {"color": plt.get_cmap("tab10")(index % 10), "linewidth": 2}


def _title(scale: str, better: str = "outer") -> str:
    what = f"rank per task ({better} = better)" if scale == "rank" else "metric value (%)"
    return f"Tracking scorecard: {what}"


def _polygons(plt: Any, card: dict[str, Any], spokes: list[tuple[str, str, str, str]],
              data: dict[str, list[float | None]], scale: str) -> Any:
    """The radar proper (three axes or more)."""
    angles = [2 * math.pi * i / len(spokes) for i in range(len(spokes))]
    figure, ax = plt.subplots(figsize=(6.4, 6.4), subplot_kw={"projection": "polar"})
    ax.set_theta_offset(math.pi / 2)  # first task at the top, the others clockwise
    ax.set_theta_direction(-1)
    for index, (name, values) in enumerate(data.items()):
        # An undefined value (e.g. IDF1 without ground-truth tracks) is a gap, not a zero.
        radius = [math.nan if v is None else v for v in values]
        style = _style(plt, name, index)
        ax.plot([*angles, angles[0]], [*radius, radius[0]], label=name, **style)
        if name != BASELINE and None not in values:
            ax.fill([*angles, angles[0]], [*radius, radius[0]], alpha=0.08,
                    color=style["color"])
        for angle, r, (task, *_rest) in zip(angles, radius, spokes, strict=True):
            hollow = card["sources"][task]["kind"] == "synthetic"
            if not math.isnan(r):
                ax.plot([angle], [r], marker="o", markersize=5, color=style["color"],
                        markerfacecolor="white" if hollow else style["color"])
    undefined = [all(values[i] is None for values in data.values()) for i in range(len(spokes))]
    ax.set_xticks(angles)
    ax.set_xticklabels([label + ("\n(no value)" if none else "")
                        for (*_rest, label), none in zip(spokes, undefined, strict=True)],
                       fontsize=9)
    ax.tick_params(axis="x", pad=12)
    for tick, angle in zip(ax.get_xticklabels(), angles, strict=True):
        side = math.sin(angle)  # clockwise from the top: > 0 on the right half
        tick.set_horizontalalignment("left" if side > 0.1 else "right" if side < -0.1
                                     else "center")  # away from the circle, not across it
    ax.set_ylim(0, 1.0)
    ax.set_yticks([0.25, 0.5, 0.75, 1.0])
    ax.set_yticklabels([] if scale == "rank" else ["25", "50", "75", "100"], fontsize=7)
    ax.set_title(_title(scale), pad=24, fontsize=11)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=2, fontsize=8,
              frameon=False)
    return figure


def _bars(plt: Any, card: dict[str, Any], spokes: list[tuple[str, str, str, str]],
          data: dict[str, list[float | None]], scale: str) -> Any:
    """One or two tasks: grouped bars (no radar polygon has fewer than three vertices)."""
    from matplotlib.patches import Patch  # lazy: optional dependency (matplotlib, [plots])

    figure, ax = plt.subplots(figsize=(3.2 + 1.6 * len(spokes), 4.8))
    width = 0.8 / len(data)
    legend = []
    for index, (name, values) in enumerate(data.items()):
        style = _style(plt, name, index)
        look = {"edgecolor": style["color"], "linewidth": 1.5,
                "linestyle": style.get("linestyle", "-"),
                "hatch": "//" if name == BASELINE else None}
        legend.append(Patch(facecolor=style["color"], label=name, **look))
        for slot, (value, (task, *_rest)) in enumerate(zip(values, spokes, strict=True)):
            if value is not None:
                hollow = card["sources"][task]["kind"] == "synthetic"
                ax.bar(slot - 0.4 + width * (index + 0.5), value, width * 0.9,
                       facecolor="white" if hollow else style["color"], **look)
    ax.set_xticks(range(len(spokes)))
    ax.set_xticklabels([label for *_rest, label in spokes], fontsize=9)
    ax.set_ylim(0, 1.0)
    ax.set_yticks([0.25, 0.5, 0.75, 1.0])
    ax.set_yticklabels(["", "", "", "best"] if scale == "rank" else ["25", "50", "75", "100"],
                       fontsize=7)
    ax.set_title(_title(scale, "higher"), fontsize=11)
    ax.legend(handles=legend, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2,
              fontsize=8, frameon=False)
    return figure
