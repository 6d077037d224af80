"""TAP-Vid everywhere a task shows up: `unitrack events`, `compare` (an honest refusal),
`report` and the scorecard (an opt-in column), on the synthetic TAP-Vid default."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.evaluation.analysis.events import load_events
from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.scorecard import _checked_request
from unitrack_env.evaluation.scorecard_plan import TASKS, ModelSpec, plan
from unitrack_env.metrics.points import THRESHOLDS

ENV = "UniTrack/TAPVid-DAVIS-v0"


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("tapvid-runs")
    out = {}
    for agent in ("static-points", "lk-points"):
        out[agent] = base / agent
        assert main(["evaluate", "--env", ENV, "--agent", agent, "--out", str(out[agent]),
                     "--quiet"]) == 0
    return out


def test_events_give_back_the_scored_metrics(runs, capsys) -> None:
    run = runs["static-points"]
    assert main(["events", str(run), "--format", "csv"]) == 0
    assert "occlusion_error" in capsys.readouterr().out
    events = load_events(run)
    metrics = json.loads((run / "metrics.json").read_text())["per_sequence"]
    assert set(events["sequence"]) == set(metrics)
    for name, seq in events.groupby("sequence"):
        pairs = seq[seq["type"].isin(["point", "occlusion_error"])]
        frames = seq[seq["type"] == "frame"]
        assert len(frames) == seq["frame"].max()  # one "frame" event per frame
        # OA: the pairs whose occlusion flag is right, of all evaluated pairs
        assert (pairs["type"] == "point").mean() == pytest.approx(metrics[name]["OA"], abs=1e-9)
        # <δ^x_avg: of the pairs visible in the ground truth, the share within each δ
        distance = pairs["distance"].dropna().to_numpy()
        delta = np.mean([np.mean(distance < d) for d in THRESHOLDS])
        # (the events file keeps 4 decimals: a distance at a threshold may round across it)
        assert delta == pytest.approx(metrics[name]["delta_x_avg"], abs=1e-3)
        # each frame's curve value: the same share over that frame's visible points
        for _, row in frames.iterrows():
            here = pairs.loc[pairs["frame"] == row["frame"], "distance"].dropna().to_numpy()
            if len(here) == 0:
                assert np.isnan(row["pck"])
            else:
                assert row["pck"] == pytest.approx(
                    np.mean([np.mean(here < d) for d in THRESHOLDS]), abs=0.02)


def test_compare_refuses_saying_why(runs, capsys) -> None:
    code = main(["compare", str(runs["static-points"]), str(runs["lk-points"])])
    err = capsys.readouterr().err
    assert code != 0
    assert "cannot compare points runs" in err and "ratios of sums" in err
    assert "Traceback" not in err


def test_report_draws_a_curve_per_sequence(runs, tmp_path, capsys) -> None:
    out = tmp_path / "report"
    assert main(["report", str(runs["static-points"]), "--out", str(out)]) == 0
    pages = sorted(out.glob("seq*.html"))
    assert len(pages) == 3
    for page in pages:
        text = page.read_text(encoding="utf-8")
        assert "δx visible per frame" in text and "<polyline" in text
        assert "No per-frame events" not in text


def test_the_scorecard_column_is_opt_in() -> None:
    assert "points" not in list(TASKS)  # the default task set is unchanged
    assert "points" in TASKS and "points" in TASKS.every()
    column = TASKS["points"]
    assert column.axis == ("UniTrack", "AJ") and column.input_size == (1, 256, 256)
    names, _ = _checked_request([ModelSpec.parse("random")], ["points"], None)
    assert names == ["points"]
    cells, _, _ = plan([ModelSpec.parse("random")], ["points"], None, generate=False)
    assert {c.agent for c in cells} == {"unitrack-points", "static-points"}
    assert {c.env_id for c in cells} == {ENV}
    assert {c.task for c in cells} == {"points"}
    with pytest.raises(ValueError, match="points"):
        _checked_request([ModelSpec.parse("random")], ["nope"], None)
