from __future__ import annotations

import json
import os
import subprocess
import sys
import traceback
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.run.runner import run
from unitrack_env.metrics.mot_results import read_result_file

ENV = "UniTrack/MOT16-v0"


def test_run_writes_official_files_and_combined_metrics(tmp_path):
    report = run(ENV, "iou", out=tmp_path, progress=False)
    assert sorted(report.records) == ["SYN-01", "SYN-02"]
    for name, record in report.records.items():
        rows = read_result_file(tmp_path / "data" / f"{name}.txt")
        assert rows.shape[1] >= 6 and record.frames == int(rows[:, 0].max())
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert set(metrics["per_sequence"]) == {"SYN-01", "SYN-02"}
    for key in ("HOTA", "MOTA", "IDF1", "IDSW"):
        assert key in metrics["combined"]
    assert metrics["combined"]["IDSW"] == sum(m["IDSW"] for m in metrics["per_sequence"].values())
    assert not list(tmp_path.rglob("*.tmp"))


def test_records_name_the_runtime_of_the_appearance_features(tmp_path):
    iou = run(ENV, "iou", out=tmp_path / "iou", progress=False, sequences=["SYN-01"])
    assert iou.records["SYN-01"].runtimes == []  # no appearance model
    record = json.loads((tmp_path / "iou" / "sequences" / "SYN-01.json").read_text())
    assert record["runtimes"] == []
    del record["runtimes"]  # a record of an earlier version reads as unrecorded
    from unitrack_env.evaluation.run.episode import SequenceRecord

    assert SequenceRecord.from_json(record).runtimes is None


def test_resume_keeps_finished_sequences(tmp_path):
    first = run(ENV, "iou", out=tmp_path, progress=False)
    kept = tmp_path / "data" / "SYN-01.txt"
    stamp = kept.stat().st_mtime_ns
    (tmp_path / "sequences" / "SYN-02.json").unlink()  # as if the run died during SYN-02
    second = run(ENV, "iou", out=tmp_path, progress=False)
    assert second.skipped == ["SYN-01"] and kept.stat().st_mtime_ns == stamp
    assert second.combined == pytest.approx(first.combined)


def test_a_run_folder_resumes_with_its_data_moved_and_replays_what_changed(tmp_path,
                                                                          mot17_root):
    """Run folders are tied to what the data and code are, not where they live: a folder copied
    to another machine (or a committed scorecard) reuses every sequence; changed data replays."""
    import shutil

    shutil.copytree(mot17_root, tmp_path / "a" / "MOT17")
    first = run("UniTrack/MOT17-v0", "iou", out=tmp_path / "a" / "run", progress=False,
                env_kwargs={"root": str(tmp_path / "a" / "MOT17")})
    shutil.copytree(tmp_path / "a" / "MOT17", tmp_path / "b" / "MOT17")
    shutil.copytree(tmp_path / "a" / "run", tmp_path / "b" / "run")
    shutil.rmtree(tmp_path / "a")
    elsewhere = {"root": str(tmp_path / "b" / "MOT17")}
    moved = run("UniTrack/MOT17-v0", "iou", out=tmp_path / "b" / "run", progress=False,
                env_kwargs=elsewhere)
    assert sorted(moved.skipped) == sorted(first.records) and not moved.replayed
    assert moved.combined == first.combined
    assert json.loads((tmp_path / "b" / "run" / "run.json").read_text())["env_kwargs"] == \
        elsewhere  # the record names where the data are now
    changed = min(first.records)
    gt = tmp_path / "b" / "MOT17" / "train" / changed / "gt" / "gt.txt"
    gt.write_text(gt.read_text().replace(",1,", ",1, ", 1))  # the same boxes, other bytes
    again = run("UniTrack/MOT17-v0", "iou", out=tmp_path / "b" / "run", progress=False,
                env_kwargs=elsewhere)
    assert list(again.replayed) == [changed]
    with pytest.raises(ValueError, match="env option root"):  # real data vs synthetic
        run("UniTrack/MOT17-v0", "iou", out=tmp_path / "b" / "run", progress=False)


def test_a_crash_mid_run_loses_no_finished_sequence(tmp_path, monkeypatch):
    from unitrack_env.agents.baselines.iou import IoUAgent

    calls = {"n": 0}
    original = IoUAgent.act

    def flaky(self, observation):
        calls["n"] += 1
        if calls["n"] > 80:  # SYN-01 has 72 frames: fail inside SYN-02
            raise KeyboardInterrupt
        return original(self, observation)

    monkeypatch.setattr(IoUAgent, "act", flaky)
    with pytest.raises(KeyboardInterrupt):
        run(ENV, "iou", out=tmp_path, progress=False)
    assert (tmp_path / "data" / "SYN-01.txt").is_file()
    assert not (tmp_path / "data" / "SYN-02.txt").exists()
    monkeypatch.setattr(IoUAgent, "act", original)
    report = run(ENV, "iou", out=tmp_path, progress=False)
    assert report.skipped == ["SYN-01"] and "SYN-02" in report.scores.per_sequence


def test_agent_errors_name_sequence_and_frame(tmp_path, monkeypatch):
    from unitrack_env.agents.baselines.iou import IoUAgent

    monkeypatch.setattr(IoUAgent, "act", lambda self, obs: 1 / 0)
    with pytest.raises(RuntimeError, match="agent 'iou' failed on sequence 'SYN-01', frame 1"):
        run(ENV, "iou", out=tmp_path, progress=False)


def test_an_agent_error_keeps_its_traceback(tmp_path, monkeypatch):
    from unitrack_env.agents.baselines.iou import IoUAgent
    from unitrack_env.evaluation.run.runner import RunFailed

    def helper(observation):
        return observation["no such key"]

    monkeypatch.setattr(IoUAgent, "act", lambda self, obs: helper(obs))
    with pytest.raises(RunFailed) as info:
        run(ENV, "iou", out=tmp_path, progress=False, sequences=["SYN-01"])
    error = info.value.errors["SYN-01"]
    assert info.value.__cause__ is error and isinstance(error.__cause__, KeyError)
    frames = traceback.extract_tb(error.__cause__.__traceback__)
    assert frames[-1].name == "helper"  # the user's own line, for pdb.post_mortem


class DuckTyped:
    """An agent by protocol only: reset and act, no close()."""

    def reset(self, observation, info):
        pass

    def act(self, observation):
        return {"ids": np.zeros(0, int), "boxes": np.zeros((0, 4))}


def test_an_agent_without_close_keeps_its_report(tmp_path):
    report = run(ENV, DuckTyped, out=tmp_path, progress=False, sequences=["SYN-01"])
    assert report.scores is not None and (tmp_path / "metrics.json").is_file()


def test_refuses_to_mix_runs_in_one_folder(tmp_path):
    run(ENV, "iou", out=tmp_path, progress=False, sequences=["SYN-01"])
    with pytest.raises(ValueError, match="already holds a different run .agent: 'iou' -> "
                                         "'fresh-ids'; agent class: "):
        run(ENV, "fresh-ids", out=tmp_path, progress=False, sequences=["SYN-01"])
    with pytest.raises(ValueError, match=r"different run \(agent option min_hits: unset -> 5\); "
                                         "choose another --out, or replace it with --overwrite"):
        run(ENV, "iou", out=tmp_path, progress=False, sequences=["SYN-01"],
            agent_kwargs={"min_hits": 5})
    report = run(ENV, "fresh-ids", out=tmp_path, progress=False, sequences=["SYN-01"],
                 overwrite=True)
    assert report.skipped == []


def test_parallel_workers_match_serial(tmp_path):
    serial = run(ENV, "iou", out=tmp_path / "a", progress=False)
    parallel = run(ENV, "iou", out=tmp_path / "b", progress=False, workers=2)
    assert parallel.combined == pytest.approx(serial.combined)
    for name in serial.records:
        assert (tmp_path / "a" / "data" / f"{name}.txt").read_text() == (
            tmp_path / "b" / "data" / f"{name}.txt").read_text()


def test_test_split_writes_results_without_scores(tmp_path):
    report = run(ENV, "iou", out=tmp_path, progress=False, env_kwargs={"split": "test"})
    assert report.scores is None and (tmp_path / "data" / "SYN-03.txt").is_file()
    assert "no ground truth" in json.loads((tmp_path / "metrics.json").read_text())["note"]


def test_cli_evaluate_score_and_errors(tmp_path, capsys):
    assert main(["evaluate", "--env", ENV, "--agent", "iou", "--out", str(tmp_path / "r"),
                 "--quiet", "--agent-arg", "min_hits=3"]) == 0
    out = capsys.readouterr().out
    assert "COMBINED" in out and "HOTA" in out and "metrics.json" in out
    assert json.loads((tmp_path / "r" / "run.json").read_text())["agent_kwargs"] == {
        "min_hits": 3}
    gt = json.loads((tmp_path / "r" / "metrics.json").read_text())
    from unitrack_env.datasets.synthetic import ensure_synthetic

    assert main(["score", "--benchmark", "MOT16", "--gt", str(ensure_synthetic("MOT16") / "train"),
                 "--results", str(tmp_path / "r" / "data"), "--out", str(tmp_path / "s.json")]) == 0
    scored = json.loads((tmp_path / "s.json").read_text())
    assert scored["combined"]["HOTA"] == pytest.approx(gt["combined"]["HOTA"])
    assert main(["evaluate", "--env", ENV, "--agent", "nope", "--out", str(tmp_path / "x")]) == 2
    assert "unknown agent 'nope'" in capsys.readouterr().err
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "SYN-01.txt").write_text("1,1,a,2,3,4,1,-1,-1,-1\n")
    assert main(["score", "--benchmark", "MOT16", "--gt", str(ensure_synthetic("MOT16") / "train"),
                 "--results", str(bad), "--allow-missing"]) == 2
    assert "line 1" in capsys.readouterr().err


def test_render_command_writes_a_video(tmp_path):
    import cv2

    path = tmp_path / "v.avi"
    assert main(["render", "--env", ENV, "--agent", "iou", "--sequence", "SYN-01",
                 "--out", str(path)]) == 0
    capture = cv2.VideoCapture(str(path))
    assert int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) == 72


def test_console_script_is_installed():
    exe = Path(sys.executable).parent / "unitrack"
    if not exe.exists():
        pytest.skip("package not installed with its console script")
    result = subprocess.run([str(exe), "list"], capture_output=True, text=True,
                            env=os.environ | {"COLUMNS": "120"}, check=True)
    assert "UniTrack/MOT17-v0" in result.stdout and "iou" in result.stdout


@pytest.mark.slow
def test_real_pets_with_iou(tmp_path, mot15_root):
    report = run("UniTrack/MOT15-v0", "iou", out=tmp_path, progress=False,
                 env_kwargs={"root": str(mot15_root)})
    assert report.records["PETS09-S2L1"].frames == 400
    assert report.combined["IDF1"] > 0.3
    np.testing.assert_array_less(0, report.combined["HOTA"])


def test_agents_are_named_by_a_name_a_reference_or_the_class(tmp_path):
    from unitrack_env.agents import make_agent

    assert isinstance(make_agent(DuckTyped), DuckTyped)
    with pytest.raises(TypeError, match="got an instance of DuckTyped .pass its class"):
        run(ENV, DuckTyped(), out=tmp_path, progress=False)
    report = run(ENV, DuckTyped, out=tmp_path, progress=False, sequences="SYN-01")
    assert list(report.records) == ["SYN-01"]  # one name, not its letters


def test_a_class_workers_cannot_import_is_refused_up_front(tmp_path):
    def local_class():
        class Local(DuckTyped):
            pass
        return Local

    with pytest.raises(ValueError, match="inside a function"):
        run(ENV, local_class(), out=tmp_path / "run", progress=False, workers=2)
    assert not (tmp_path / "run").exists()


def test_a_script_without_the_main_guard_is_refused_before_any_work(tmp_path):
    script = tmp_path / "unguarded.py"
    script.write_text("from unitrack_env.evaluation.run.runner import run\n"
                      f"run({ENV!r}, 'iou', out={str(tmp_path / 'run')!r}, workers=2)\n")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode != 0 and not (tmp_path / "run").exists()
    assert "under 'if __name__ == \"__main__\":'" in done.stderr
    assert f"{script} (line 2)" in done.stderr
