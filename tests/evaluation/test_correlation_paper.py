"""The paper's correlation study (section 3.3, Figure 4) from its own Table 2 numbers.

The inputs and their sources are in data/paper_correlation.json. The scorecard is built from
Table 2 (the bolded, better-of-two-layers value of each cell, as the paper ranks them) and goes
through ``unitrack scorecard --compare ... --external`` like a user's would; the test prints
its coefficients beside the paper's stated ranges (docs/correlation-study.md explains the
difference).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from scipy import stats

from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.scorecard.plan import BASELINE, TASKS
from unitrack_env.evaluation.scorecard.radar import axes

DATA = json.loads((Path(__file__).parent / "data" / "paper_correlation.json").read_text())
#: Table 2 column of each task's radar axis (the scorecard's tracking metric per task).
AXIS_COLUMN = {"sot": "SOT AUC_XCorr", "vos": "VOS J-mean", "mot": "MOT IDF1",
               "mots": "MOTS IDF1", "posetrack": "PoseTrack IDF1"}


def bolded(model: str, column: str) -> float:
    """The better of a Table 2 cell's [layer3, layer4] values (the paper's bolded one)."""
    pair = DATA["models"][model]["table2"][DATA["columns"].index(column)]
    return min(pair) if column in DATA["lower_is_better"] else max(pair)


def source(task: str) -> dict:
    return {"kind": "benchmark", "root": f"/data/{task}", "env_id": TASKS[task].env_ids[0]}


def paper_card() -> dict:
    """A scorecard holding Table 2's axis metrics for the models with a probe number."""
    rows = []
    for model in [*DATA["models"], BASELINE]:
        for task, head, metric, _ in axes({"tasks": list(AXIS_COLUMN), "sources": {
                t: {"kind": "benchmark"} for t in AXIS_COLUMN}}):
            head = TASKS[task].baseline.label if model == BASELINE else head
            value = None if model == BASELINE else bolded(model, AXIS_COLUMN[task]) / 100
            rows.append({"model": model, "task": task, "head": head, "combined": {
                metric: value}, "per_sequence": {}, "source": source(task)})
    return {"version": 1, "models": list(DATA["models"]), "tasks": list(AXIS_COLUMN),
            "sources": {t: source(t) for t in AXIS_COLUMN},
            "rows": rows, "runtime": "torch"}


def test_paper_study_from_table2_and_published_probe_accuracies(tmp_path, capsys):
    card = tmp_path / "paper" / "scorecard.json"
    card.parent.mkdir()
    card.write_text(json.dumps(paper_card()))
    probe = tmp_path / "probe.csv"
    probe.write_text("model,probe:imagenet\n" + "".join(
        f"{name},{entry['probe']}\n" for name, entry in DATA["models"].items()))
    out = tmp_path / "study"
    assert main(["scorecard", "--compare", str(card), "--external", str(probe),
                 "--out", str(out)]) == 0
    capsys.readouterr()
    result = json.loads((out / "correlation.json").read_text())
    rows = {c["task"]: c for c in result["correlations"]}
    assert set(rows) == set(AXIS_COLUMN) and result["metrics"] == ["probe:imagenet"]
    x = [DATA["models"][m]["probe"] for m in DATA["models"]]
    for task, column in AXIS_COLUMN.items():
        y = [bolded(m, column) for m in DATA["models"]]
        assert rows[task]["n"] == len(DATA["models"]) == 15
        assert rows[task]["pearson"] == pytest.approx(stats.pearsonr(x, y).statistic)
        assert rows[task]["spearman"] == pytest.approx(stats.spearmanr(x, y).statistic)
        assert rows[task]["pearson_ci"][0] < rows[task]["pearson"] < rows[task]["pearson_ci"][1]
    paper = DATA["paper"]
    with capsys.disabled():
        print(f"\nImageNet linear probe vs tracking, {len(x)} models (paper: "
              f"{paper['models']} models, {paper['tasks']} tasks)")
        for c in rows.values():
            low, high = c["pearson_ci"]
            print(f"  {c['title']:27s} r = {c['pearson']:+.2f} [{low:+.2f}, {high:+.2f}]  "
                  f"rho = {c['spearman']:+.2f}  {c['verdict']}")
        r = [c["pearson"] for c in rows.values()]
        rho = [c["spearman"] for c in rows.values()]
        print(f"  Pearson r   {min(r):+.2f} .. {max(r):+.2f}   paper "
              f"{paper['pearson'][0]:+.2f} .. {paper['pearson'][1]:+.2f}")
        print(f"  Spearman rho {min(rho):+.2f} .. {max(rho):+.2f}   paper "
              f"{paper['spearman'][0]:+.2f} .. {paper['spearman'][1]:+.2f}")
        print("  other Table 2 columns (r / rho at the better layer, layer3, layer4):")
        for i, column in enumerate(DATA["columns"]):
            sign = -1 if column in DATA["lower_is_better"] else 1
            cells = []
            for layer in ("best", 0, 1):
                y = [sign * (bolded(m, column) if layer == "best" else
                             DATA["models"][m]["table2"][i][layer]) for m in DATA["models"]]
                cells.append(f"{stats.pearsonr(x, y).statistic:+.2f} / "
                             f"{stats.spearmanr(x, y).statistic:+.2f}")
            print(f"    {column:16s} " + "   ".join(cells))
    # The paper's finding, which these inputs reproduce: no strong correlation on any task
    # (|r|, |rho| < 0.5), and VOS the one mildly inverse task.
    assert all(abs(v) < 0.5 for v in r + rho)
    assert rows["vos"]["pearson"] < 0 and rows["vos"]["spearman"] < 0
    assert min(r) == rows["vos"]["pearson"]
    assert {c["verdict"] for c in rows.values()} == {
        "no clear correlation: an interval contains 0"}
    for name in ("correlation.md", "correlation-probe-imagenet.png",
                 "correlation-probe-imagenet.svg"):
        assert (out / name).is_file(), name
