"""Scorecard tables: Markdown laid out like the UniTrack paper's Table 2, and CSV.

Table 2 has one row per representation and, per task, its metric columns (SOT: AUC of the
XCorr and DCF heads; VOS: J-mean; MOT and MOTS: IDF1, HOTA; PoseTrack: IDF1, IDs). Here
every task's headline metrics are shown the same way, in percent (counts as integers), the
best model of each column in bold, the appearance-free baselines in a last row. A task
played on the embedded synthetic data has its header marked with a dagger and a footnote,
so that no one mistakes its numbers for benchmark results; fixtures (small real samples) are
marked too.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..analysis.tables import COUNT_METRICS
from .plan import BASELINE, TASKS

#: Header marks of the data sources.
MARKS = {"benchmark": "", "fixture": "*", "synthetic": "†"}


def columns(card: dict[str, Any]) -> list[tuple[str, str, str]]:
    """(task, head, metric) of every column, in the scorecard's task order."""
    out = []
    for task in card["tasks"]:
        spec = TASKS[task]
        for head in spec.heads:
            for metric in head.metrics:
                out.append((task, head.label, metric))
    return out


def value(card: dict[str, Any], model: str, task: str, head: str, metric: str) -> float | None:
    """The combined metric of one row, or None."""
    if model == BASELINE:
        head = TASKS[task].baseline.label
    for row in card["rows"]:
        if (row["model"], row["task"], row["head"]) == (model, task, head):
            return row["combined"].get(metric)
    return None


def _cell(metric: str, number: float | None) -> str:
    if number is None:
        return "-"
    return f"{number:.0f}" if metric in COUNT_METRICS else f"{100 * number:.1f}"


def _lower_is_better(task: str, metric: str) -> bool:
    return metric in TASKS[task].lower_is_better


def markdown_table(card: dict[str, Any]) -> str:
    """The scorecard as a Markdown table (one row per model, then the baselines)."""
    cols = columns(card)
    rows = [*card["models"], BASELINE]
    head = ["Representation"]
    for task, label, metric in cols:
        arrow = "↓" if _lower_is_better(task, metric) else "↑"
        several = len(TASKS[task].heads) > 1
        name = f"{metric} ({label})" if several else metric
        mark = MARKS[card["sources"][task]["kind"]]
        head.append(f"{TASKS[task].title}{mark} {name} {arrow}")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    best: dict[int, float] = {}
    for i, (task, label, metric) in enumerate(cols):
        numbers = [v for m in card["models"] if (v := value(card, m, task, label, metric))
                   is not None]
        if numbers:
            best[i] = min(numbers) if _lower_is_better(task, metric) else max(numbers)
    for model in rows:
        cells = [model if model != BASELINE else f"*{model}*"]
        for i, (task, label, metric) in enumerate(cols):
            number = value(card, model, task, label, metric)
            text = _cell(metric, number)
            if model != BASELINE and number is not None and number == best.get(i) \
                    and len(card["models"]) > 1:
                text = f"**{text}**"
            cells.append(text)
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    for task in card["tasks"]:
        source = card["sources"][task]
        where = source["root"] or "the embedded synthetic data (not benchmark numbers)"
        mark = MARKS[source["kind"]]
        lines.append(f"- {TASKS[task].title}{mark}: {source['env_id']}, {source['kind']}: {where}")
    lines.append("")
    lines.append("† synthetic data: a self-test, not a benchmark result. * fixture: real "
                 "data, but a small sample of the benchmark.")
    lines.append("Association heads without motion cues, as in the paper's Table 2, unless "
                 "the scorecard was made with --motion.")
    if card.get("runtime"):
        lines.append(f"Appearance models ran on {card['runtime']}.")
    notes = dict.fromkeys(TASKS[task].note for task in card["tasks"] if task in TASKS)
    lines.extend(note for note in notes if note)
    return "\n".join(lines) + "\n"


def ran_on(labels: dict[str, int], unrecorded: int) -> str:
    """How the appearance models ran, for the card, from the cells' own records.

    ``labels`` counts the model cells per runtime label (``openvino (auto, checked against
    torch)``); ``unrecorded`` cells were stored before records kept it. One runtime reads as
    its label; several name their cells: ``openvino in 40 cells, torch in 2 cells``.
    """
    if len(labels) == 1 and not unrecorded:
        return next(iter(labels))
    parts = [f"{label} in {n} cell{'s' * (n != 1)}" for label, n in sorted(
        labels.items(), key=lambda item: (-item[1], item[0]))]
    if unrecorded:
        parts.append(f"an unrecorded runtime in {unrecorded} cell{'s' * (unrecorded != 1)} "
                     "(stored by an earlier version)")
    return ", ".join(parts)


def rows_csv(card: dict[str, Any]) -> str:
    """One CSV row per (model, task, head, sequence or COMBINED) with every metric."""
    metrics = sorted({k for row in card["rows"] for k in row["combined"]})
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["model", "task", "head", "sequence", "source", "root", *metrics])
    for row in card["rows"]:
        source = row["source"]
        entries = [*row["per_sequence"].items(), ("COMBINED", row["combined"])]
        for sequence, values in entries:
            writer.writerow([row["model"], row["task"], row["head"], sequence, source["kind"],
                             source["root"] or "", *(
                                 "" if values.get(m) is None else repr(values[m])
                                 for m in metrics)])
    return buffer.getvalue()


def polygon_values(card: dict[str, Any],
                   spokes: list[tuple[str, str, str, str]]) -> dict[str, list[float | None]]:
    """Each model's (and the baselines') value on each radar axis ``(task, head, metric, _)``."""
    return {model: [value(card, model, task, head, metric) for task, head, metric, _ in spokes]
            for model in [*card["models"], BASELINE]}


def merge_cards(paths: Sequence[Path]) -> dict[str, Any]:
    """Several ``scorecard.json`` files as one scorecard (for ``--compare``).

    Models keep their labels, prefixed with their folder's name where two files use the same
    label; the baselines and the data sources are the first file's. A task whose data source
    differs between the files is refused: its numbers would not be comparable.
    """
    cards = []
    for path in paths:
        try:
            cards.append((path, json.loads(Path(path).read_text())))
        except (OSError, ValueError) as exc:
            raise ValueError(f"{path}: not a readable scorecard.json ({exc})") from None
    first = cards[0][1]
    merged: dict[str, Any] = {**first, "models": [], "rows": [],
                              "compared": [str(p) for p in paths]}
    labels = [m for _, card in cards for m in card["models"]]
    for path, card in cards:
        for task, source in card["sources"].items():
            known = merged["sources"].setdefault(task, source)
            if (known["kind"], known["root"]) != (source["kind"], source["root"]):
                raise ValueError(f"{path}: task {task} was scored on {source['kind']} data "
                                 f"({source['root']}), the first scorecard on {known['kind']} "
                                 f"({known['root']}); their numbers are not comparable")
        rename = {m: f"{Path(path).parent.name}/{m}" if labels.count(m) > 1 else m
                  for m in card["models"]}
        merged["models"] += list(rename.values())
        for row in card["rows"]:
            if row["model"] == BASELINE:
                if card is first:
                    merged["rows"].append(row)
                continue
            merged["rows"].append({**row, "model": rename[row["model"]]})
        merged["tasks"] += [t for t in card["tasks"] if t not in merged["tasks"]]
    runtimes = dict.fromkeys(card.get("runtime") or "unrecorded" for _, card in cards)
    if set(runtimes) != {"unrecorded"}:
        merged["runtime"] = " / ".join(runtimes)  # each file's, in order
    return merged
