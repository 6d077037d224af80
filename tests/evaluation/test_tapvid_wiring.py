"""TAP-Vid everywhere a task shows up: `unitrack events`, `compare` (paired intervals),
`report` and the scorecard (an opt-in column), on the synthetic TAP-Vid default."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from unitrack_env.evaluation.analysis.compare import COMBINED, jackknife_interval
from unitrack_env.evaluation.analysis.events import load_events
from unitrack_env.evaluation.analysis.intervals import (
    compare_runs,
    count_replicates,
    run_intervals,
)
from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.scorecard.card import _checked_request
from unitrack_env.evaluation.scorecard.plan import TASKS, ModelSpec, plan
from unitrack_env.metrics.points import COLUMNS, THRESHOLDS

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


def test_compare_recomputes_the_scored_metrics(runs, capsys) -> None:
    a, b = runs["static-points"], runs["lk-points"]
    comparison = compare_runs(a, b)
    for run, side in ((a, "a"), (b, "b")):
        scored = json.loads((run / "metrics.json").read_text())
        for name, row in comparison.rows.items():
            expected = scored["combined"] if name == COMBINED else scored["per_sequence"][name]
            for metric, diff in row.items():  # the point estimate is the scored number, exactly
                assert getattr(diff, side) == expected[metric], (run, name, metric)
    for row in comparison.rows.values():
        assert set(row) == set(COLUMNS)
        for diff in row.values():
            assert diff.low <= diff.diff <= diff.high
    assert main(["compare", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    assert COMBINED in out and "AJ" in out
    assert run_intervals(a).keys() == set(COLUMNS)


class _Share:
    """A hand-built benchmark: per sequence the share of hits, then the mean over sequences."""

    @staticmethod
    def metrics_of_counts(counts) -> dict[str, float]:
        total = float(counts["trials"])
        return {"share": float(counts["hits"]) / total if total else float("nan")}


def _counts(p: float, frames: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    trials = np.full(frames, 10)
    return {"hits": rng.binomial(trials, p), "trials": trials}


def test_count_jackknife_on_a_known_difference() -> None:
    rng = np.random.default_rng(3)
    a = {f"s{i}": _counts(0.8, 200, rng) for i in range(3)}
    b = {f"s{i}": _counts(0.6, 200, rng) for i in range(3)}
    empty = {"hits": np.zeros(200, int), "trials": np.zeros(200, int)}
    a["none"], b["none"] = empty, empty  # no trials: NaN, left out of the mean
    blocks = dict.fromkeys(a, 40)
    ra, rb = (count_replicates(c, blocks, _Share()) for c in (a, b))
    share = [c["hits"].sum() / c["trials"].sum() for n, c in a.items() if n != "none"]
    assert ra[COMBINED]["share"][0] == pytest.approx(np.mean(share), abs=1e-12)
    assert len(ra[COMBINED]["share"][1]) == 4 * 5  # one replicate per block of each
    (pa, reps_a), (pb, reps_b) = ra[COMBINED]["share"], rb[COMBINED]["share"]
    low, high = jackknife_interval(pa - pb, reps_a - reps_b)
    assert low < 0.2 < high  # the true difference (0.8 - 0.6)
    assert 0.005 < (high - low) / 2 < 0.05  # about 1.96 * sqrt(2 * .2 / 6000 + ...) * t
    same = count_replicates(a, blocks, _Share())[COMBINED]["share"]
    assert jackknife_interval(0.0, same[1] - reps_a) == (0.0, 0.0)  # identical runs


def test_report_draws_a_curve_per_sequence(runs, tmp_path, capsys) -> None:
    out = tmp_path / "report"
    assert main(["report", str(runs["static-points"]), "--out", str(out)]) == 0
    pages = sorted(out.glob("seq*.html"))
    assert len(pages) == 3
    for page in pages:
        text = page.read_text(encoding="utf-8")
        assert "δx visible per frame" in text and "<polyline" in text
        assert "No per-frame events" not in text


def test_report_pictures_the_worst_frames_with_their_points(runs, tmp_path) -> None:
    out = tmp_path / "report"
    assert main(["report", str(runs["static-points"]), "--out", str(out)]) == 0
    thumbs = sorted(p for p in out.glob("img*/low-*.jpg")
                    if not p.stem.endswith(("-full", "-prev", "-next")))
    assert thumbs, "no pictures of low-PCK frames"
    full = sorted(out.glob("img*/low-*-full.jpg"))
    pixels = np.asarray(Image.open(full[0]).convert("RGB"), int)
    red = (pixels[..., 0] > 200) & (pixels[..., 1] < 60) & (pixels[..., 2] < 60)
    green = (pixels[..., 1] > 180) & (pixels[..., 0] < 60) & (pixels[..., 2] < 60)
    assert red.sum() > 20 and green.sum() > 20  # predicted and true points drawn
    pages = sorted(out.glob("img*/low-*.html"))
    assert pages
    text = pages[0].read_text(encoding="utf-8")
    assert "PCK ≤" in text and "worst quarter of frames" in text
    assert full[0].name in text


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
