"""`unitrack compare`: the paired block bootstrap and what it says about little data."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.evaluation.analysis.compare import (
    COMBINED,
    block_length,
    block_weights,
    compare_stats,
    jackknife_weights,
)
from unitrack_env.evaluation.analysis.intervals import compare_runs
from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.run.runner import run
from unitrack_env.metrics.events_mot import preprocessed_frames
from unitrack_env.metrics.mot_stats import mot_stats

ENV = "UniTrack/MOT16-v0"


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("compare")
    kwargs = {"decode_frames": False}
    run(ENV, "iou", out=root / "a", progress=False, env_kwargs=kwargs)
    run(ENV, "iou", out=root / "b", progress=False, env_kwargs=kwargs,
        agent_kwargs={"iou_threshold": 0.7})
    return root / "a", root / "b"


def test_block_weights_are_circular_blocks() -> None:
    w = block_weights(10, 500, np.random.default_rng(0), length=3)
    assert w.shape == (500, 10) and (w.sum(1) == 10).all()
    # five blocks per sequence: long enough to hold whole identities (docs/report.md)
    assert block_length(400) == 80 and block_length(4) == 1 and block_length(1) == 1
    assert block_length(8) == 2 and block_length(1001) == 201
    # every frame is drawn equally often on average (circular blocks have no edge effect)
    assert np.allclose(w.mean(0), 1.0, atol=0.15)
    single = block_weights(5, 1, np.random.default_rng(1), length=5)
    assert (single == 1).all()  # one block of the whole sequence is a rotation of it


def test_jackknife_weights_leave_out_one_block_each() -> None:
    w = jackknife_weights(11, 3)
    assert w.shape == (4, 11)
    assert (w.sum(1) == [8, 8, 8, 9]).all()  # the last block is the 2 frames left
    assert ((1 - w).sum(0) == 1).all()  # every frame is left out exactly once
    assert (w[1, 3:6] == 0).all() and w[1, :3].all() and w[1, 6:].all()


def test_interval_methods() -> None:
    from scipy.stats import t as student

    from unitrack_env.evaluation.analysis.compare import interval, jackknife_interval

    boot = np.random.default_rng(0).normal(1.0, 0.1, 4000)
    for method in ("bc", "percentile", "basic"):
        low, high = interval(1.0, boot, method)
        assert low == pytest.approx(0.804, abs=0.02) and high == pytest.approx(1.196, abs=0.02)
    shifted_low, _ = interval(1.1, boot, "bc")  # the bootstrap sits below the estimate
    assert shifted_low > 0.85
    with pytest.raises(ValueError, match="interval must be one of"):
        interval(1.0, boot, "normal")
    # the jackknife of a mean is the textbook t interval: mean +- t(n-1) s / sqrt(n)
    x = np.random.default_rng(1).normal(2.0, 1.0, 12)
    left_out = (x.sum() - x) / (len(x) - 1)
    low, high = jackknife_interval(float(x.mean()), left_out)
    half = student.ppf(0.975, 11) * x.std(ddof=1) / np.sqrt(12)
    assert low == pytest.approx(x.mean() - half) and high == pytest.approx(x.mean() + half)
    assert interval(3.0, left_out[:1], "jackknife") == (3.0, 3.0)  # one block: no spread


def test_a_run_against_itself_differs_by_exactly_nothing(two_runs) -> None:
    a, _ = two_runs
    comp = compare_runs(a, a, resamples=50)
    for row in comp.rows.values():
        for d in row.values():
            assert d.a == d.b and d.diff == d.low == d.high == 0.0
            assert not d.significant


def test_two_runs_have_paired_intervals_around_their_difference(two_runs) -> None:
    a, b = two_runs
    comp = compare_runs(a, b, resamples=300, seed=1)
    metrics = json.loads((a / "metrics.json").read_text())
    assert list(comp.rows) == [*metrics["per_sequence"], COMBINED]
    for seq, row in comp.rows.items():
        expected = metrics["combined"] if seq == COMBINED else metrics["per_sequence"][seq]
        for name, d in row.items():
            assert d.a == pytest.approx(expected[name], abs=1e-9), (seq, name)
            assert np.isfinite([d.low, d.high]).all() and d.low <= d.high
            assert d.significant == (d.reliable and (d.low > 0 or d.high < 0))
    again = compare_runs(a, b, resamples=300, seed=1)
    assert again.to_json() == comp.to_json()  # seeded


def test_too_little_data_is_said_plainly(two_runs, tmp_path) -> None:
    a, _ = two_runs
    frames = 4
    gt = np.array([[t, g, 10 + 30 * g + t, 10, 20, 40, 1, -1, -1, -1]
                   for t in range(1, frames + 1) for g in (1, 2)], dtype=float)
    trk = gt.copy()
    trk[:, 1] += 100
    trk[-1, 1] = 999  # a switch in the last frame
    sa = {"tiny": mot_stats(preprocessed_frames(gt, gt, frames, "MOT15"))}
    sb = {"tiny": mot_stats(preprocessed_frames(gt, trk, frames, "MOT15"))}
    rows, blocks = compare_stats(sa, sb, resamples=200)
    assert rows["tiny"]["MOTA"].diff > 0
    from unitrack_env.evaluation.analysis.compare import few_data_notes

    notes = few_data_notes({"tiny": frames}, blocks, "frames")
    assert any("too little data" in n for n in notes)
    from unitrack_env.evaluation.analysis.compare import unreliable_rows

    assert unreliable_rows({"tiny": frames}, blocks) == ["tiny", COMBINED]
    assert any("tiny: only 4 frames" in n for n in notes)


def _pair(frames: int, switch_at: int) -> tuple[dict, dict]:
    gt = np.array([[t, g, 10 + 60 * g + t % 7, 10, 20, 40, 1, -1, -1, -1]
                   for t in range(1, frames + 1) for g in (1, 2, 3)], dtype=float)
    trk = gt.copy()
    trk[:, 1] += 100
    trk[(trk[:, 0] >= switch_at) & (trk[:, 1] == 101), 1] = 999  # one switch
    trk = trk[(trk[:, 0] % 9 != 0) | (trk[:, 1] != 102)]  # misses every 9th frame
    return (mot_stats(preprocessed_frames(gt, gt, frames, "MOT15")),
            mot_stats(preprocessed_frames(gt, trk, frames, "MOT15")))


def test_enough_frames_give_a_reliable_interval_around_the_difference() -> None:
    from unitrack_env.evaluation.analysis.compare import unreliable_rows

    (a1, b1), (a2, b2) = _pair(120, 30), _pair(150, 100)
    sa, sb = {"s1": a1, "s2": a2}, {"s1": b1, "s2": b2}
    for method in ("jackknife", "percentile"):
        rows, blocks = compare_stats(sa, sb, resamples=100, method=method)
        assert blocks == {"s1": 24, "s2": 30}
        for row in rows.values():
            for name, d in row.items():
                assert d.low <= d.diff <= d.high, (method, name)
                assert d.diff >= 0  # B is A with a switch and misses
    assert unreliable_rows({"s1": 120, "s2": 150}, blocks) == []
    assert unreliable_rows({"s1": 60, "s2": 150}, {"s1": 12, "s2": 30}) == ["s1"]
    seq_rows, _ = compare_stats(sa, sb, level="sequences")
    assert seq_rows[COMBINED]["MOTA"].high - seq_rows[COMBINED]["MOTA"].low > 0
    with pytest.raises(ValueError, match="interval must be one of"):
        compare_stats(sa, sb, method="normal")


def test_sequence_level_resampling_runs(two_runs) -> None:
    a, b = two_runs
    comp = compare_runs(a, b, resamples=100, level="sequences")
    assert any("unstable" in n for n in comp.notes)
    with pytest.raises(ValueError, match="level must be"):
        compare_runs(a, b, resamples=10, level="videos")


def test_compare_command(two_runs, capsys, tmp_path) -> None:
    a, b = two_runs
    assert main(["compare", str(a), str(b), "--resamples", "100"]) == 0
    out = capsys.readouterr().out
    for metric in ("HOTA", "IDF1", "MOTA", "DetA", "AssA"):
        assert f"COMBINED           {metric}" in out
    assert "95% interval" in out and "paired block jackknife (frames)" in out
    assert "(too little data)" in out and "(too\n" not in out  # issue 42: cut at 80 columns
    assert all(line.count("[") == line.count("]") for line in out.splitlines())
    assert main(["compare", str(a), str(b), "--interval", "percentile", "--resamples", "50"]) == 0
    assert "paired block bootstrap (frames), 50 resamples" in capsys.readouterr().out
    assert main(["compare", str(a), str(b), "--resamples", "50", "--format", "json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert set(payload["rows"]["COMBINED"]) == {"HOTA", "DetA", "AssA", "IDF1", "MOTA"}
    other = tmp_path / "other"
    shutil.copytree(a, other)
    metrics = json.loads((other / "metrics.json").read_text())
    metrics["per_sequence"] = {"ELSEWHERE": {}}
    (other / "metrics.json").write_text(json.dumps(metrics))
    assert main(["compare", str(a), str(other)]) == 2
    assert "no scored sequence in common" in capsys.readouterr().err


def test_run_and_scorecard_intervals(two_runs, tmp_path) -> None:
    from unitrack_env.evaluation.analysis.intervals import run_intervals
    from unitrack_env.evaluation.scorecard.intervals import write_card_intervals

    a, _ = two_runs
    combined = json.loads((a / "metrics.json").read_text())["combined"]
    intervals = run_intervals(a, resamples=200)
    assert set(intervals) == {"HOTA", "DetA", "AssA", "IDF1", "MOTA"}
    for name, (low, high) in intervals.items():
        assert low < high and low - 0.05 < combined[name] < high + 0.05, name
    out = tmp_path / "sc"
    shutil.copytree(a, out / "cells" / "m" / "mot" / "UniTrack")
    card = {"models": ["m"], "tasks": ["mot"], "rows": [
        {"model": "m", "task": "mot", "head": "UniTrack", "combined": combined}]}
    md, js = write_card_intervals(out, card, resamples=100)
    cells = {c["metric"]: c for c in json.loads(js.read_text())}
    assert cells["IDF1"]["low"] < cells["IDF1"]["value"] < cells["IDF1"]["high"]
    assert "| m | mot | UniTrack | HOTA |" in md.read_text()
