"""Issue 40 item 5: the scorecard's MOT column on DanceTrack, an opt-in column of its own."""

from __future__ import annotations

from unitrack_env.evaluation.scorecard.plan import TASKS, ModelSpec, Source, data_source, plan
from unitrack_env.evaluation.scorecard.table import markdown_table

DANCE = "UniTrack/DanceTrack-v0"


def test_dancetrack_is_an_opt_in_column_and_the_default_card_is_unchanged():
    assert "dancetrack" in TASKS and "dancetrack" in TASKS.every()
    assert "dancetrack" not in list(TASKS)  # the default card: the paper's tasks only
    assert list(TASKS) == ["sot", "vos", "mot", "mots", "posetrack", "pose-prop", "vis"]
    assert TASKS["mot"].env_ids[0] == "UniTrack/MOT16-v0"  # the MOT column itself unchanged
    column = TASKS["dancetrack"]
    assert (column.title, column.env_ids, column.opt_in) == ("DanceTrack", (DANCE,), True)
    assert [h.agent for h in (*column.heads, column.baseline)] == ["unitrack", "iou"]


def test_dancetrack_under_data_is_played_else_the_synthetic_one(tmp_path):
    assert data_source(tmp_path, TASKS["dancetrack"]) == Source("synthetic", None, DANCE)
    (tmp_path / "DanceTrack").mkdir()
    source = data_source(tmp_path, TASKS["dancetrack"])
    assert source == Source("benchmark", str((tmp_path / "DanceTrack").resolve()), DANCE)
    assert data_source(tmp_path, TASKS["mot"]).kind == "synthetic"  # MOT's own data only


def test_cells_play_the_val_split_and_the_table_marks_dancetrack():
    cells, sources, _ = plan([ModelSpec.parse("random")], ["dancetrack"], None,
                             generate=False)
    assert {(c.head, c.env_id, c.sequence, c.frames) for c in cells} == {
        ("UniTrack", DANCE, "dancetrack0004", 40), ("IoU baseline", DANCE, "dancetrack0004", 40)}
    card = {"tasks": ["dancetrack"], "models": ["random"],
            "sources": {"dancetrack": {"kind": "synthetic", "root": None, "env_id": DANCE}},
            "rows": [{"model": "random", "task": "dancetrack", "head": "UniTrack",
                      "combined": {"IDF1": 0.5, "HOTA": 0.4, "MOTA": 0.3, "IDSW": 2}}]}
    table = markdown_table(card)
    assert "| DanceTrack† IDF1 ↑ |" in table
    assert f"- DanceTrack†: {DANCE}, synthetic" in table


def test_real_layout_under_data_with_detections_is_planned(tmp_path):
    from unitrack_env.datasets.synthetic.cache import ensure_synthetic
    from unitrack_env.datasets.synthetic.dance_sports import KIND

    (tmp_path / "DanceTrack").symlink_to(ensure_synthetic("DanceTrack", KIND))
    cells, sources, pending = plan([ModelSpec.parse("random")], ["dancetrack"], tmp_path)
    assert sources["dancetrack"].kind == "benchmark" and not pending
    assert {(c.sequence, c.frames, c.env_kwargs["root"]) for c in cells} == {
        ("dancetrack0004", 40, str((tmp_path / "DanceTrack").resolve()))}
