"""The paper's correlation study on a scorecard: tracking against other evaluations.

Each model (scorecard row) may carry numbers from other evaluations of the same network:
ImageNet linear-probe top-1, surface-normal error, a segmentation mIoU... Named
``KIND:NAME[:lower]`` (``probe:imagenet``, ``normals:error:lower``; ``:lower`` when a smaller
number is better), given in ``--model`` (``moco.pth,label=MoCo-v2,probe:imagenet=71.1``) or
in a CSV of model x metric (``--external FILE``: a ``model`` column of scorecard labels, one
column per metric). For each metric and task (the task's radar axis, e.g. MOT's IDF1) the
study writes Pearson's r and Spearman's rho over the models with both numbers
(:mod:`.correlation`: bootstrap intervals, "too few models" below five), ``correlation.md``
and ``.json`` and one scatter figure per metric with a panel per task, as the paper's
Figure 4 (:mod:`.correlation_plot`). Lower-is-better numbers are negated before correlating,
as the paper does with surface-normal error ("negative mean error ... to represent
accuracy"), so a positive coefficient always means "better here goes with better there".
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

from unitrack_env.io import atomic_write_text

from .correlation import correlate
from .correlation_plot import draw_scatter, figure_stem
from .plan import TASKS
from .radar import axes
from .table import value as card_value

#: Direction suffixes of a metric name.
DIRECTIONS = ("lower", "higher")


def metric_direction(name: str) -> tuple[str, bool]:
    """``(name without the direction suffix, lower is better)``; a bad name is refused."""
    parts = name.split(":")
    if len(parts) < 2 or not all(parts):
        raise ValueError(f"external metric '{name}': name it KIND:NAME (e.g. probe:imagenet), "
                         "with :lower when a smaller number is better")
    if parts[-1] in DIRECTIONS:
        if len(parts) < 3:
            raise ValueError(f"external metric '{name}': KIND:NAME before :{parts[-1]}")
        return ":".join(parts[:-1]), parts[-1] == "lower"
    return name, False


def _number(text: str, where: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{where}: '{text}' is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"{where}: '{text}' is not a finite number")
    return value


def split_model_text(text: str) -> tuple[str, dict[str, float]]:
    """``--model`` text without its external metrics, and those metrics.

    ``moco.pth,label=MoCo-v2,probe:imagenet=71.1`` -> (``moco.pth,label=MoCo-v2``,
    ``{"probe:imagenet": 71.1}``): an option whose key holds a colon is an external metric.
    """
    weights, *options = text.split(",")
    kept, metrics = [weights], {}
    for option in options:
        key, sep, value = option.strip().partition("=")
        if ":" not in key:
            kept.append(option)
            continue
        if not sep:
            raise ValueError(f"--model '{text}': external metric '{key}' needs =VALUE")
        metric_direction(key)
        metrics[key] = _number(value.strip(), f"--model '{text}': {key}")
    return ",".join(kept), metrics


def read_external_csv(path: str | Path) -> dict[str, dict[str, float]]:
    """``{model label: {metric: value}}`` from a CSV (header ``model,KIND:NAME,...``).

    Empty cells are missing values; anything else that is not a number is refused with its
    line and column.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise ValueError(f"--external {path}: cannot read it ({exc.strerror})") from None
    rows = list(csv.reader(text.splitlines()))
    if not rows or not rows[0] or rows[0][0].strip() != "model" or len(rows[0]) < 2:
        raise ValueError(f"{path}, line 1: the header must be model,KIND:NAME[,...] "
                         "(e.g. model,probe:imagenet)")
    header = [name.strip() for name in rows[0]]
    for name in header[1:]:
        try:
            metric_direction(name)
        except ValueError as exc:
            raise ValueError(f"{path}, line 1: {exc}") from None
    out: dict[str, dict[str, float]] = {}
    for line, row in enumerate(rows[1:], start=2):
        if not any(cell.strip() for cell in row):
            continue
        if len(row) != len(header):
            raise ValueError(f"{path}, line {line}: {len(row)} fields, the header has "
                             f"{len(header)}")
        model = row[0].strip()
        if model in out:
            raise ValueError(f"{path}, line {line}: model '{model}' is listed twice")
        out[model] = {name: _number(cell.strip(), f"{path}, line {line}, column {name}")
                      for name, cell in zip(header[1:], row[1:], strict=True) if cell.strip()}
    return out


def merge_externals(*sources: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
    """One table from several; a value given twice differently is refused."""
    merged: dict[str, dict[str, float]] = {}
    for source in sources:
        for model, metrics in source.items():
            mine = merged.setdefault(model, {})
            for name, value in metrics.items():
                if name in mine and mine[name] != value:
                    raise ValueError(f"model '{model}': {name} is given twice ({mine[name]:g} "
                                     f"and {value:g})")
                mine[name] = value
    return merged


def _tracking_axes(card: dict[str, Any]) -> list[tuple[str, str, str, str, bool]]:
    """(task, head, metric, title, lower is better) of each task's radar axis."""
    return [(task, head, metric, f"{TASKS[task].title} {metric} ({head})",
             metric in TASKS[task].lower_is_better)
            for task, head, metric, _ in axes(card)]


def study(card: dict[str, Any], externals: dict[str, dict[str, float]], *,
          resamples: int = 2000) -> dict[str, Any]:
    """The correlation of every external metric with every task's axis, over the models."""
    models = list(card["models"])
    names = sorted({name for metrics in externals.values() for name in metrics})
    results = []
    for name in names:
        plain, lower = metric_direction(name)
        for task, head, metric, title, track_lower in _tracking_axes(card):
            points = []
            for model in models:
                x = externals.get(model, {}).get(name)
                y = card_value(card, model, task, head, metric)
                if x is not None and y is not None:
                    points.append({"model": model, "x": x, "y": y})
            xs = [-p["x"] if lower else p["x"] for p in points]
            ys = [-p["y"] if track_lower else p["y"] for p in points]
            found = correlate(xs, ys, resamples=resamples)
            results.append({"metric": name, "metric_name": plain, "lower_is_better": lower,
                            "task": task, "head": head, "tracking_metric": metric,
                            "title": title, "source": card["sources"][task]["kind"],
                            "scatter": points, **found.to_dict()})
    return {"version": 1, "models": models, "metrics": names,
            "unmatched": sorted(set(externals) - set(models)),
            "without_values": {name: [m for m in models if name not in externals.get(m, {})]
                               for name in names},
            "resamples": resamples, "correlations": results}


def _coefficient(value: float | None, interval: list[float] | None) -> str:
    if value is None:
        return "-"
    text = f"{value:+.2f}"
    return text + (f" [{interval[0]:+.2f}, {interval[1]:+.2f}]" if interval else "")


def markdown(result: dict[str, Any]) -> str:
    """``correlation.md``: one table per external metric."""
    lines = ["# Correlation study", "",
             "Pearson's r and Spearman's rho between each task's tracking metric (the radar "
             "axis) and each other evaluation, over the models with both numbers; 95% "
             f"percentile bootstrap intervals over models ({result['resamples']} resamples). "
             "A lower-is-better number is negated first, so a positive coefficient means "
             "better there goes with better here.", ""]
    for name in result["metrics"]:
        rows = [c for c in result["correlations"] if c["metric"] == name]
        lines += [f"## {name}", "", "| task | models | Pearson r [95%] | Spearman rho [95%] | "
                  "verdict |", "|---|---|---|---|---|"]
        for c in rows:
            synthetic = " [synthetic data]" if c["source"] == "synthetic" else ""
            lines.append(f"| {c['title']}{synthetic} | {c['n']} | "
                         f"{_coefficient(c['pearson'], c['pearson_ci'])} | "
                         f"{_coefficient(c['spearman'], c['spearman_ci'])} | {c['verdict']} |")
        missing = result["without_values"][name]
        if missing:
            lines += ["", f"Left out (no {name} value): {', '.join(missing)}."]
        lines.append("")
    if result["unmatched"]:
        lines.append(f"Not in the scorecard (ignored): {', '.join(result['unmatched'])}.")
    return "\n".join(lines).rstrip() + "\n"


def write_correlation(out: Path, card: dict[str, Any],
                      externals: dict[str, dict[str, float]]) -> list[Path]:
    """``correlation.json``, ``correlation.md`` and a scatter figure per metric (PNG, SVG)."""
    result = study(card, externals)
    atomic_write_text(out / "correlation.json", json.dumps(result, indent=2, allow_nan=False))
    atomic_write_text(out / "correlation.md", markdown(result))
    written = [out / "correlation.json", out / "correlation.md"]
    for name in result["metrics"]:
        rows = [c for c in result["correlations"] if c["metric"] == name]
        written += draw_scatter(rows, out / f"correlation-{figure_stem(name)}")
    return written

