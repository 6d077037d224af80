"""The scorecard's opt-in SOT columns on LaSOT and GOT-10k val; the default card unchanged."""

from __future__ import annotations

from pathlib import Path

from unitrack_env.benchmarks.sot_columns import SPREAD
from unitrack_env.benchmarks.views import Head, ScorecardColumn
from unitrack_env.datasets.lasot import GOT10K_SYNTHETIC
from unitrack_env.datasets.synthetic.cache import ensure_synthetic
from unitrack_env.evaluation.scorecard.plan import TASKS, ModelSpec, plan
from unitrack_env.evaluation.scorecard.table import markdown_table

MODELS = [ModelSpec.parse("imagenet-lite0")]


def test_the_default_task_set_and_its_sot_column_are_unchanged() -> None:
    assert list(TASKS) == ["sot", "vos", "mot", "mots", "posetrack", "pose-prop", "vis"]
    metrics = ("AUC", "Precision@20px")
    before = ScorecardColumn(  # the OTB column as it was declared before the opt-in ones
        "SOT", ("UniTrack/OTB-v0",),
        (Head("unitrack-xcorr", "XCorr", metrics), Head("unitrack-dcf", "DCF", metrics)),
        Head("repeat-box", "repeat-box", metrics, appearance=False),
        ("XCorr", "AUC"), order=1, input_size=(3, 520, 520), head_seconds=0.02,
        note=SPREAD)  # (the footer line of how far SOT cells move, added with exact crops)
    task = TASKS["sot"]
    assert ScorecardColumn(**{k: getattr(task, k) for k in before.__dataclass_fields__}) \
        == before


def test_lasot_and_got10k_are_opt_in_columns_named_by_their_benchmark() -> None:
    every = TASKS.every()
    assert every.index("sot") < every.index("sot-lasot") < every.index("sot-got10k") \
        < every.index("vos")
    lasot, got = TASKS["sot-lasot"], TASKS["sot-got10k"]
    assert (lasot.opt_in, lasot.title, lasot.env_ids) == (True, "SOT (LaSOT)",
                                                          ("UniTrack/LaSOT-v0",))
    assert lasot.heads[0].metrics == ("AUC", "Precision@20px", "NormPrecision")
    assert (got.opt_in, got.title, got.env_ids) == (True, "SOT (GOT-10k val)",
                                                    ("UniTrack/GOT10k-v0",))
    assert got.heads[1].metrics == ("AO", "SR0.5") and got.axis == ("XCorr", "AO")


def test_lasot_column_plays_the_fixture_under_data(shared_data) -> None:
    cells, sources, _ = plan(MODELS, ["sot-lasot"], shared_data)
    assert (sources["sot-lasot"].env_id, sources["sot-lasot"].kind) == \
        ("UniTrack/LaSOT-v0", "fixture")
    lasot = [c for c in cells if c.task == "sot-lasot"]
    assert {(c.head, c.sequence, c.frames) for c in lasot} == {
        (head, "airplane-1", 300) for head in ("XCorr", "DCF", "repeat-box")}
    assert all(c.folder.parts[1] == "sot-lasot" for c in lasot)  # its own cell folders


def test_got10k_column_reads_val_under_data_and_is_marked_in_the_table(tmp_path: Path) -> None:
    data = tmp_path / "data"
    data.mkdir()
    (data / "GOT-10k").symlink_to(ensure_synthetic("GOT-10k", GOT10K_SYNTHETIC))
    cells, sources, _ = plan(MODELS, ["sot-got10k"], data)
    assert (sources["sot-got10k"].env_id, sources["sot-got10k"].kind) == \
        ("UniTrack/GOT10k-v0", "benchmark")
    val = {n.strip() for n in (data / "GOT-10k/val/list.txt").read_text().split()}
    assert {c.sequence for c in cells} == val
    card = {"tasks": ["sot", "sot-got10k"], "models": ["m"],
            "sources": {"sot": {"kind": "synthetic", "root": None, "env_id": "UniTrack/OTB-v0"},
                        "sot-got10k": {"kind": "benchmark", "root": "/d/GOT-10k",
                                       "env_id": "UniTrack/GOT10k-v0"}},
            "rows": [{"model": "m", "task": "sot-got10k", "head": "XCorr",
                      "combined": {"AO": 0.5, "SR0.5": 0.25}}]}
    table = markdown_table(card)
    assert "| SOT† AUC (XCorr) ↑ |" in table
    assert "SOT (GOT-10k val) AO (XCorr) ↑ | SOT (GOT-10k val) SR0.5 (XCorr) ↑" in table
    assert "| m | - | - | - | - | 50.0 | 25.0 | - | - |" in table
    assert "- SOT (GOT-10k val): UniTrack/GOT10k-v0, benchmark: /d/GOT-10k" in table
    # how far SOT cells move, once under the table however many SOT columns it has
    assert table.count(SPREAD) == 1 and "at most 0.2 points" in SPREAD
    card["tasks"] = ["sot-got10k"]
    assert SPREAD in markdown_table(card)
