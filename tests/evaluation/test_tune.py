"""``unitrack tune``: the search space checked before anything runs, resume after Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.tune.search import (
    Dimension,
    apply,
    check_space,
    parse_dimension,
    setting_digest,
    trial_cost,
)

REPO = Path(__file__).resolve().parents[2]


def test_space_syntax():
    assert parse_dimension("new_track_score=0.3..0.9") == Dimension("new_track_score", 0.3, 0.9)
    assert parse_dimension("max_tracks=10..60") == Dimension("max_tracks", 10, 60)
    assert parse_dimension("lr=1e-4..1e-1:log") == Dimension("lr", 1e-4, 0.1, log=True)
    assert parse_dimension("use_motion=True|False").choices == (True, False)
    assert parse_dimension("similarity=rsm|cosine").choices == ("rsm", "cosine")
    for bad, message in [("x", "give NAME=LOW..HIGH"), ("x=0.9..0.1", "need LOW < HIGH"),
                         ("x=0..1:log", "LOW > 0 on a log scale"), ("x=a..b", "must be numbers"),
                         ("x=1", "two or more different choices"), ("x=0..1:sqrt", ":log")]:
        with pytest.raises(ValueError, match=message):
            parse_dimension(bad)


def test_settings_add_to_the_fixed_options():
    base = {"iou_threshold": 0.4, "weights": "random"}
    setting = {"appearance_threshold": 0.6, "new_track_score": 0.7}
    assert apply(base, setting) == {"iou_threshold": 0.4, "appearance_threshold": 0.6,
                                    "weights": "random", "new_track_score": 0.7}
    assert base == {"iou_threshold": 0.4, "weights": "random"}
    assert setting_digest({"a": 1, "b": 2}) == setting_digest({"b": 2, "a": 1})


@pytest.mark.parametrize(("space", "message"), [
    (["newtrack_score=0.3..0.9"], "has no option 'newtrack_score'"),
    (["use_motion=1..3"], "option 'use_motion' must be bool"),
    (["weights=0.1..0.5"], "option 'weights' must be str"),
    (["appearance_treshold=0.5..0.9"], "has no option 'appearance_treshold'"),
    (["duplicate_iou=0.5..1.5"], r"duplicate_iou must be in \[0, 1\]"),
    (["new_track_score=0.3..0.9", "new_track_score=0.1..0.2"], "names an option twice"),
])
def test_bad_space_is_refused_before_anything_runs(space, message):
    with pytest.raises(ValueError, match=message):
        check_space("unitrack", [parse_dimension(s) for s in space], {})


def test_cli_refuses_bad_requests_with_one_line(tmp_path, capsys):
    common = ["tune", "--env", "UniTrack/MOT16-v0", "--agent", "unitrack", "--out",
              str(tmp_path / "t"), "--space", "new_track_score=0.3..0.9"]
    for extra, message in [
        (["--tune-sequences", "SYN-01", "--validation-sequences", "SYN-01", "--metric",
          "IDF1"], "SYN-01 in both --tune-sequences and --validation-sequences"),
        (["--tune-sequences", "SYN-01", "--validation-sequences", "SYN-02", "--metric",
          "IDF2"], "--metric IDF2: UniTrack/MOT16-v0 scores HOTA, IDF1"),
        (["--tune-sequences", "SYN-09", "--validation-sequences", "SYN-02", "--metric",
          "IDF1"], "SYN-09"),
    ]:
        assert main(common + extra) == 2
        assert message in capsys.readouterr().err
    assert not (tmp_path / "t").exists()  # refused before anything ran


def test_trial_cost_is_later_trials_over_the_first():
    rows = [{"state": "COMPLETE", "played": 1, "seconds": 10.0, "cpu_seconds": 8.0},
            {"state": "COMPLETE", "played": 0, "seconds": 0.1},  # a setting drawn again
            {"state": "COMPLETE", "played": 1, "seconds": 2.0, "cpu_seconds": 2.0},
            {"state": "FAIL", "played": None, "seconds": None},
            {"state": "COMPLETE", "played": 1, "seconds": 4.0, "cpu_seconds": 2.0}]
    rows = [{"number": i, **row} for i, row in enumerate(rows)]
    assert trial_cost(rows) == {"first_seconds": 10.0, "later_median_seconds": 3.0,
                                "ratio": 0.3, "first_cpu_seconds": 8.0,
                                "later_median_cpu_seconds": 2.0, "cpu_ratio": 0.25}
    assert trial_cost(rows[:2]) is None
    assert trial_cost(rows[1:]) is None  # the first trial was interrupted: not recorded


def test_an_interrupted_trial_is_queued_again_with_its_setting(tmp_path):
    """A trial stopped by Ctrl-C (Optuna marks it failed) resumes: its setting is drawn
    first, so its run folder (same digest) keeps its finished sequences."""
    optuna = pytest.importorskip("optuna")
    from unitrack_env.evaluation.tune.search import _study

    study = _study(optuna, tmp_path, "maximize", 0)
    done = study.ask({"x": optuna.distributions.FloatDistribution(0, 1)})
    study.tell(done, 0.5)
    stopped = study.ask({"x": optuna.distributions.FloatDistribution(0, 1)})
    study.tell(stopped, state=optuna.trial.TrialState.FAIL)
    resumed = _study(optuna, tmp_path, "maximize", 0)
    waiting = [t for t in resumed.trials if t.state.name == "WAITING"]
    assert [t.system_attrs["fixed_params"] for t in waiting] == [stopped.params]
    assert len(_study(optuna, tmp_path, "maximize", 0).trials) == 3  # queued once only


def _command(out: Path, trials: int) -> list[str]:
    return [sys.executable, "-m", "unitrack_env.evaluation.cli", "tune", "--env",
            "UniTrack/MOT16-v0", "--agent", "unitrack", "--agent-arg", "input_size=(320, 192)",
            "--tune-sequences", "SYN-01", "--validation-sequences", "SYN-02",
            "--metric", "IDF1", "--trials", str(trials), "--out", str(out),
            "--space", "new_track_score=0.3..0.9",
            "--space", "appearance_threshold=0.5..0.9",
            "--space", "use_motion=True|False"]


@pytest.mark.slow
def test_tune_resumes_after_ctrl_c_and_validates(tmp_path):
    """Ctrl-C after the first finished trial, then resumed to the end (3 trials to keep it
    short on CI; the acceptance run of docs/tune.md has 8)."""
    out = tmp_path / "tune"
    env = {**os.environ, "PYTHONPATH": str(REPO), "COLUMNS": "160"}
    first = subprocess.Popen(_command(out, 3), env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 900
    while time.monotonic() < deadline and first.poll() is None and not list(
            out.glob("trials/*/metrics.json")):
        time.sleep(0.5)
    first.send_signal(signal.SIGINT)
    _, err = first.communicate(timeout=300)
    assert first.returncode == 130, err
    assert "interrupted" in err
    kept = {p.parent.name for p in out.glob("trials/*/metrics.json")}
    assert kept  # the finished trial is kept
    again = subprocess.run(_command(out, 3), env=env, capture_output=True, text=True,
                           timeout=3600)
    assert again.returncode == 0, again.stderr
    result = json.loads((out / "tune.json").read_text())
    complete = [r for r in result["history"] if r["state"] == "COMPLETE"]
    assert len(complete) == 3
    assert kept <= {Path(r["folder"]).name for r in complete}  # not played again
    assert "best: trial" in again.stdout and "95% interval" in again.stdout
    assert "cost: " in again.stdout  # measured, or why not (the first trial was stopped)
    validation = result["validation"]
    assert validation["low"] <= validation["diff"] <= validation["high"]
    print(again.stdout)


def test_ray_domains_keep_the_bounds_of_the_space():
    """Ray's integer upper bound is exclusive: the space's is inclusive."""
    pytest.importorskip("ray.tune")
    from unitrack_env.evaluation.tune.ray_trials import _domain

    ints = _domain(parse_dimension("max_age=10..60"))
    assert (ints.lower, ints.upper) == (10, 61)
    floats = _domain(parse_dimension("lr=1e-4..1e-1:log"))
    assert (floats.lower, floats.upper) == (1e-4, 0.1)
    assert "LogUniform" in type(floats.get_sampler()).__name__
    assert _domain(parse_dimension("use_motion=True|False")).categories == [True, False]


@pytest.mark.slow
def test_tune_on_ray_runs_trial_folders_and_restores_after_ctrl_c(tmp_path):
    """Ray Tune trials on a local Ray, Ctrl-C after the first finished trial, then the same
    command: the experiment is restored, the finished trial is not played again."""
    pytest.importorskip("ray.tune")
    out = tmp_path / "tune"
    env = {**os.environ, "PYTHONPATH": str(REPO), "COLUMNS": "160"}
    command = [*_command(out, 2), "--backend", "ray"]
    first = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
    deadline = time.monotonic() + 900
    while time.monotonic() < deadline and first.poll() is None and not list(
            out.glob("trials/*/metrics.json")):
        time.sleep(0.5)
    first.send_signal(signal.SIGINT)
    _, err = first.communicate(timeout=300)
    assert first.returncode == 130, err
    assert list(out.glob("trials/*/metrics.json"))  # the finished trial is kept
    # Its played sequences' records and result files: a trial Ray had not yet recorded as
    # complete when Ctrl-C came runs again, but resumes its folder (it is scored again, so
    # its metrics.json may be rewritten) without playing a kept sequence again.
    stamps = {p: p.stat().st_mtime_ns for p in out.glob("trials/*/sequences/*.json")}
    stamps |= {p: p.stat().st_mtime_ns for p in out.glob("trials/*/data/*")}
    assert stamps
    again = subprocess.run(command, env=env, capture_output=True, text=True, timeout=1800)
    assert again.returncode == 0, again.stderr
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps  # not played again
    result = json.loads((out / "tune.json").read_text())
    assert result["backend"] == "ray"
    rows = result["history"]
    assert [r["state"] for r in rows] == ["COMPLETE", "COMPLETE"]
    for row in rows:  # ordinary run folders named by their setting, scored by the runner
        assert row["folder"] == f"trials/{setting_digest(row['params'])}"
        assert (out / row["folder"] / "metrics.json").is_file()
    assert "72 computed" in rows[0]["feature_cache"]  # the first trial ran the backbone
    assert "0 computed" in rows[1]["feature_cache"]  # the second read it from the cache
    assert result["best"]["value"] == max(r["value"] for r in rows)
    validation = result["validation"]
    assert validation["low"] <= validation["diff"] <= validation["high"]
    assert "best: trial" in again.stdout and "95% interval" in again.stdout
    print(again.stdout)
