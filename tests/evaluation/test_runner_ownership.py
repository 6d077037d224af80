"""One owner per output folder: a lock, a manifest, --overwrite that deletes only ours."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import textwrap
import time
import warnings
from pathlib import Path

import pytest

from unitrack_env.datasets.synthetic import ensure_synthetic
from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.run.ownership import LOCK, MANIFEST, OutputInUse, hold_folder
from unitrack_env.evaluation.run.runner import OutputError, run

ENV = "UniTrack/MOT16-v0"


def _on_disk(out: Path) -> set[str]:
    return {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()}


def _manifest(out: Path) -> dict:
    return json.loads((out / MANIFEST).read_text())


def test_the_manifest_lists_every_file_a_run_wrote(tmp_path):
    out = tmp_path / "run"
    run(ENV, "iou", out=out, progress=False)
    assert set(_manifest(out)["files"]) | {MANIFEST} == _on_disk(out)
    assert _manifest(out)["playing"] == [] and not (out / LOCK).exists()


def test_overwrite_deletes_only_our_files_and_names_the_others(tmp_path):
    out = tmp_path / "mine"  # the user's own folder: their data/ and sequences/, no run
    for rel in ("data/own_tracker.txt", "sequences/notes.json", "README.txt"):
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        (out / rel).write_text("the user's own file\n")
    with pytest.warns(UserWarning, match=r"--overwrite kept 3 file\(s\).*README.txt, "
                                         r"data/own_tracker.txt, sequences/notes.json"):
        run(ENV, "iou", out=out, progress=False, overwrite=True)
    assert (out / "data" / "own_tracker.txt").read_text() == "the user's own file\n"
    with pytest.warns(UserWarning, match="kept 3 file"):
        run(ENV, "iou", out=out, progress=False, sequences=["SYN-01"], overwrite=True)
    # a run of ours replaced: SYN-02's files were ours and go
    assert not (out / "data" / "SYN-02.txt").exists()
    assert (out / "sequences" / "notes.json").is_file() and (out / "README.txt").is_file()


def test_a_file_of_the_user_where_a_run_would_write_is_refused(tmp_path, capsys):
    out = tmp_path / "mine"
    (out / "data").mkdir(parents=True)
    (out / "data" / "SYN-01.txt").write_text("results of the user's own tracker\n")
    with pytest.raises(OutputError, match="no run of ours wrote.*data/SYN-01.txt"):
        run(ENV, "iou", out=out, progress=False)
    for overwrite in ([], ["--overwrite"]):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # --overwrite names the file it kept, then refuses
            assert main(["evaluate", "--env", ENV, "--agent", "iou", "--out", str(out),
                         "--quiet", *overwrite]) == 2
        err = capsys.readouterr().err
        assert "no run of ours wrote" in err and "data/SYN-01.txt" in err
    assert (out / "data" / "SYN-01.txt").read_text() == "results of the user's own tracker\n"


def test_a_run_without_a_manifest_is_adopted_and_resumed(tmp_path):
    out = tmp_path / "run"
    run(ENV, "iou", out=out, progress=False)
    (out / MANIFEST).unlink()  # a folder written before manifests existed
    assert run(ENV, "iou", out=out, progress=False).skipped == ["SYN-01", "SYN-02"]
    assert "data/SYN-01.txt" in _manifest(out)["files"]
    run(ENV, "iou", out=out, progress=False, overwrite=True)


def _holder(out: Path) -> subprocess.Popen:
    """Another process holding ``out``'s lock until killed."""
    script = textwrap.dedent(f"""
        import sys, time
        from unitrack_env.evaluation.run.ownership import hold_folder
        with hold_folder({str(out)!r}, "agent other on {ENV}"):
            print("held", flush=True)
            time.sleep(120)
    """)
    child = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True,
                             env=os.environ | {"PYTHONPATH": os.pathsep.join(sys.path)})
    assert child.stdout.readline().strip() == "held"
    return child


def test_a_second_process_is_refused_naming_the_holder(tmp_path, capsys):
    out = tmp_path / "run"
    child = _holder(out)
    try:
        with pytest.raises(OutputInUse, match=rf"pid {child.pid} on {socket.gethostname()}"):
            run(ENV, "iou", out=out, progress=False)
        assert main(["evaluate", "--env", ENV, "--agent", "iou", "--out", str(out),
                     "--quiet"]) == 2
        err = capsys.readouterr().err
        assert "in use by another run" in err and "agent other on" in err and "since" in err
    finally:
        child.kill()
        child.wait()
    assert not (out / "run.json").exists()  # nothing written while another held it
    with pytest.warns(UserWarning, match="took over the lock of a run that is no longer"):
        run(ENV, "iou", out=out, progress=False)  # the dead holder's lock is taken over


def test_the_lock_is_held_in_this_process_too(tmp_path):
    out = tmp_path / "run"
    with hold_folder(out, "test"), pytest.raises(OutputInUse, match=f"pid {os.getpid()}"):
        run(ENV, "iou", out=out, progress=False)


def test_stale_temporaries_are_removed_at_the_start(tmp_path):
    out = tmp_path / "run"
    run(ENV, "iou", out=out, progress=False)
    left = [out / ".metrics.json.k2j4h5g1.tmp", out / "data" / ".SYN-01.txt.ab_d1234.tmp",
            out / "sequences" / ".SYN-02.json.zzzzzzzz.tmp"]
    for path in left:
        path.write_text("half a file from a killed write")
    (out / ".user.tmp").write_text("not one of ours: no random part")
    run(ENV, "iou", out=out, progress=False)
    assert not any(path.exists() for path in left) and (out / ".user.tmp").exists()


@pytest.mark.parametrize("where", ["runs/a", "train/runs"])
def test_out_inside_root_resumes_instead_of_replaying(tmp_path, where):
    root = tmp_path / "MOT16"
    shutil.copytree(ensure_synthetic("MOT16"), root)
    out = root / where
    first = run(ENV, "iou", out=out, env_kwargs={"root": str(root)}, progress=False)
    again = run(ENV, "iou", out=out, env_kwargs={"root": str(root)}, progress=False)
    assert again.replayed == {} and again.skipped == ["SYN-01", "SYN-02"]
    assert again.combined == first.combined


def test_a_killed_run_leaves_its_claim(tmp_path, monkeypatch):
    from unitrack_env.evaluation.run import episode, runner, serial

    out = tmp_path / "run"
    calls = []

    def crash(out_, env, record, bench, *played):  # the first results are written, then a "kill"
        bench.write(out_ / "data", record.sequence, episode.recorded_results(env))
        calls.append(record.sequence)
        raise KeyboardInterrupt

    monkeypatch.setattr(serial, "save_episode", crash)  # where the sequences are played
    monkeypatch.setattr(runner, "settle", lambda *args: None)  # killed: no bookkeeping
    with pytest.raises(KeyboardInterrupt):
        run(ENV, "iou", out=out, progress=False)
    assert _manifest(out)["playing"] == ["SYN-01", "SYN-02"]
    monkeypatch.undo()
    run(ENV, "iou", out=out, progress=False, overwrite=True)  # its half sequence was ours
    assert _manifest(out)["playing"] == []


@pytest.mark.slow  # two interpreters; the holder-in-a-subprocess test above runs by default
def test_two_processes_into_one_new_folder_one_is_refused(tmp_path):
    out = tmp_path / "both"
    slow = tmp_path / "slow.py"
    slow.write_text("import time\nfrom unitrack_env.agents.baselines.iou import IoUAgent\n\n"
                    "class Slow(IoUAgent):\n    def act(self, observation):\n"
                    "        time.sleep(0.1)\n        return super().act(observation)\n")
    command = [sys.executable, "-m", "unitrack_env.evaluation.cli", "evaluate", "--env", ENV,
               "--out", str(out), "--quiet", "--agent"]
    env = os.environ | {"PYTHONPATH": os.pathsep.join(sys.path)}
    first = subprocess.Popen([*command, f"{slow}:Slow"], env=env, stderr=subprocess.PIPE,
                             text=True)
    deadline = time.monotonic() + 120
    while not (out / LOCK).exists() and first.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    second = subprocess.run([*command, "iou"], env=env, capture_output=True, text=True)
    first_err = first.communicate()[1]
    assert sorted([first.returncode, second.returncode]) == [0, 2], (first_err, second.stderr)
    assert "in use by another run" in second.stderr and "Slow" in second.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    agent = json.loads((out / "run.json").read_text())["agent"]
    assert metrics["agent"] == agent  # never metrics under one name from the other's files


def test_a_manifest_json_of_another_tool_is_not_trusted(tmp_path):
    out = tmp_path / "theirs"
    (out / "data").mkdir(parents=True)
    (out / "data" / "notes.txt").write_text("keep me\n")
    (out / MANIFEST).write_text(json.dumps({"files": ["data/notes.txt"]}))
    with pytest.raises(ValueError, match="not a manifest of unitrack-env"):
        run(ENV, "iou", out=out, progress=False, overwrite=True)
    assert (out / "data" / "notes.txt").read_text() == "keep me\n"


def test_a_scorecard_folder_has_one_owner_too(tmp_path, capsys):
    out = tmp_path / "card"
    with hold_folder(out, "scorecard"):
        assert main(["scorecard", "--model", "random", "--tasks", "sot", "--out",
                     str(out)]) == 2
    assert "in use by another run" in capsys.readouterr().err
    assert not (out / "cells").exists()
