"""Faults the runner survives: failing sequences, changed inputs, dead parents, bad disks."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from unitrack_env.datasets.synthetic import ensure_synthetic
from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.run.runner import OutputError, RunFailed, run

ENV = "UniTrack/MOT16-v0"


@pytest.fixture
def mot16(tmp_path: Path) -> Path:
    """A private copy of the synthetic MOT16 data set (tests may damage it)."""
    root = tmp_path / "MOT16"
    shutil.copytree(ensure_synthetic("MOT16"), root)
    return root


def _corrupt_first_frame(root: Path, sequence: str) -> Path:
    frame = sorted((root / "train" / sequence / "img1").iterdir())[0]
    data = frame.read_bytes()
    frame.write_bytes(data[: len(data) // 2])  # truncated JPEG: no end-of-image marker
    return frame


@pytest.mark.parametrize(("workers", "bad", "good"), [(1, "SYN-01", "SYN-02"),
                                                      (1, "SYN-02", "SYN-01"),
                                                      (2, "SYN-02", "SYN-01")])
def test_a_corrupt_frame_fails_its_sequence_only(tmp_path, mot16, workers, bad, good, capsys):
    frame = _corrupt_first_frame(mot16, bad)
    out = tmp_path / "run"
    with pytest.raises(RunFailed) as failed:
        run(ENV, "iou", out=out, env_kwargs={"root": str(mot16)}, workers=workers,
            progress=False)
    assert list(failed.value.failures) == [bad]
    assert str(frame) in failed.value.failures[bad]
    assert (out / "sequences" / f"{good}.json").is_file()
    assert not (out / "sequences" / f"{bad}.json").exists()
    code = main(["evaluate", "--env", ENV, "--root", str(mot16), "--agent", "iou", "--out",
                 str(out), "--workers", str(workers), "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and str(frame) in err and "Traceback" not in err
    assert "1 sequence(s) failed" in err


@pytest.mark.parametrize("workers", [1, 2])
def test_a_sequence_refused_at_the_door_fails_alone(tmp_path, workers, capsys):
    """OTB and DAVIS read a whole sequence to count its frames: one with a malformed ground
    truth fails alone, before any frame is played, and the others are played and kept."""
    root = tmp_path / "OTB"
    shutil.copytree(ensure_synthetic("OTB", "otb"), root)
    truth = root / "SynWalker" / "groundtruth_rect.txt"
    truth.write_text("10,20,30\n" + truth.read_text())
    out = tmp_path / "run"
    with pytest.raises(RunFailed) as failed:
        run("UniTrack/OTB-v0", "repeat-box", out=out, env_kwargs={"root": str(root)},
            workers=workers, progress=False)
    assert list(failed.value.failures) == ["SynWalker"]
    assert "groundtruth_rect.txt" in failed.value.failures["SynWalker"]
    assert sorted(p.name for p in (out / "sequences").iterdir()) == [
        "SynCrossing.json", "SynLateStart.json"]
    code = main(["evaluate", "--env", "UniTrack/OTB-v0", "--root", str(root), "--agent",
                 "repeat-box", "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and "1 sequence(s) failed" in err and "SynWalker" in err
    assert "Traceback" not in err


def test_changed_detections_replay_that_sequence_only(tmp_path, mot16):
    out = tmp_path / "run"
    first = run(ENV, "iou", out=out, env_kwargs={"root": str(mot16)}, progress=False)
    (mot16 / "train" / "SYN-01" / "det" / "det.txt").write_text("")
    with pytest.warns(UserWarning, match="det.txt"):
        second = run(ENV, "iou", out=out, env_kwargs={"root": str(mot16)}, progress=False)
    assert second.skipped == ["SYN-02"]
    assert "inputs" in second.replayed["SYN-01"]
    assert second.records["SYN-01"].digest != first.records["SYN-01"].digest
    assert second.scores.per_sequence["SYN-01"]["HOTA"] == 0


def test_an_edited_agent_file_replays_its_sequences(tmp_path):
    agent = tmp_path / "my_agent.py"
    agent.write_text("from unitrack_env.agents.baselines.iou import IoUAgent\n\n"
                     "class Mine(IoUAgent):\n    pass\n")
    out = tmp_path / "run"
    run(ENV, f"{agent}:Mine", out=out, progress=False)
    assert run(ENV, f"{agent}:Mine", out=out, progress=False).skipped == ["SYN-01", "SYN-02"]
    agent.write_text(agent.read_text() + "# tuned\n")
    agent.write_text(agent.read_text().replace("pass", "def act(self, observation):\n"
                                               "        raise ValueError('the new code')"))
    with pytest.raises(RunFailed, match="the new code"):  # replayed with the edited class
        run(ENV, f"{agent}:Mine", out=out, progress=False)
    agent.write_text(agent.read_text().replace("raise ValueError('the new code')",
                                               "return super().act(observation)"))
    again = run(ENV, f"{agent}:Mine", out=out, progress=False)
    assert again.skipped == [] and "code changed" in again.replayed["SYN-01"]


def test_an_edited_helper_module_beside_the_agent_file_replays_its_sequences(tmp_path):
    """The agent's code is its file and what it imports beside it (or from the agents
    package): a change one import away is a change of the agent."""
    (tmp_path / "my_agent.py").write_text(
        "from my_helpers import Base\n\nclass Mine(Base):\n    pass\n")
    helpers = tmp_path / "my_helpers.py"
    helpers.write_text("from unitrack_env.agents.baselines.iou import IoUAgent as Base\n")
    reference = f"{tmp_path / 'my_agent.py'}:Mine"
    out = tmp_path / "run"
    sys.path.insert(0, str(tmp_path))  # how a user's agent finds its own modules
    try:
        first = run(ENV, reference, out=out, progress=False)
        assert run(ENV, reference, out=out, progress=False).skipped == sorted(first.records)
        helpers.write_text(helpers.read_text() + "# retuned\n")
        again = run(ENV, reference, out=out, progress=False)
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop("my_helpers", None)
    assert again.skipped == [] and sorted(again.replayed) == sorted(first.records)
    assert "the agent's code changed since it was played (my_helpers.py)" in \
        again.replayed["SYN-01"]


def test_restamp_keeps_sequences_across_a_code_only_edit_and_checks_it(tmp_path, mot16,
                                                                        capsys):
    """--restamp keeps a sequence only where the code is all that changed, and says which
    files; changed data, or a record without a code manifest, still replay."""
    agent = tmp_path / "my_agent.py"
    agent.write_text("from unitrack_env.agents.baselines.iou import IoUAgent\n\n"
                     "class Mine(IoUAgent):\n    pass\n")
    out = tmp_path / "run"
    command = ["evaluate", "--env", ENV, "--root", str(mot16), "--agent", f"{agent}:Mine",
               "--out", str(out), "--quiet"]
    assert main(command) == 0
    records = {p.name: p.read_text() for p in (out / "sequences").iterdir()}
    agent.write_text(agent.read_text() + "# a comment cannot move a box\n")
    old = json.loads(records["SYN-02.json"])
    del old["code"]  # a record that cannot show what code played it
    (out / "sequences" / "SYN-02.json").write_text(json.dumps(old))
    assert main(command + ["--restamp"]) == 0
    printed = capsys.readouterr().out
    assert "re-stamped SYN-01: kept across your edit of my_agent.py" in printed
    assert "replayed SYN-02:" in printed and "holds no code manifest" in printed
    assert (out / "sequences" / "SYN-01.json").read_text() != records["SYN-01.json"]
    assert run(ENV, f"{agent}:Mine", out=out, env_kwargs={"root": str(mot16)},
               progress=False).skipped == ["SYN-01", "SYN-02"]  # both stamped for today's code
    agent.write_text(agent.read_text() + "# another\n")
    detections = mot16 / "train" / "SYN-01" / "det" / "det.txt"
    detections.write_text(detections.read_text().replace(",", ", ", 1))
    report = run(ENV, f"{agent}:Mine", out=out, env_kwargs={"root": str(mot16)},
                 progress=False, restamp=True)
    assert report.restamped == {"SYN-02": ["my_agent.py"]}
    assert "data files or options changed too" in report.replayed["SYN-01"]


def test_a_moved_agent_file_and_checkpoint_resume_and_changed_weights_replay(tmp_path):
    """An agent given by its file and an option naming a file (a checkpoint) count by base
    name and content: moved elsewhere with the run folder they resume every sequence, and
    other bytes at the same path replay."""
    code = ("from unitrack_env.agents.baselines.iou import IoUAgent\n\n"
            "class Mine(IoUAgent):\n    def __init__(self, weights: str, **options):\n"
            "        super().__init__(**options)\n"
            "        self.scale = float(open(weights).read())\n")
    here, there = tmp_path / "here", tmp_path / "there"
    here.mkdir()
    (here / "my_agent.py").write_text(code)
    (here / "weights.txt").write_text("1.0")

    def play(folder: Path):
        return run(ENV, f"{folder / 'my_agent.py'}:Mine", out=folder / "run", progress=False,
                   agent_kwargs={"weights": str(folder / "weights.txt")})

    first = play(here)
    shutil.copytree(here, there)
    shutil.rmtree(here)
    moved = play(there)
    assert sorted(moved.skipped) == sorted(first.records) and not moved.replayed
    (there / "weights.txt").write_text("2.0")
    again = play(there)
    assert again.skipped == [] and sorted(again.replayed) == sorted(first.records)
    (there / "other.txt").write_text("2.0")
    with pytest.raises(ValueError, match="agent option weights"):  # another file: another run
        run(ENV, f"{there / 'my_agent.py'}:Mine", out=there / "run", progress=False,
            agent_kwargs={"weights": str(there / "other.txt")})


def test_a_tampered_result_file_is_replayed(tmp_path):
    out = tmp_path / "run"
    first = run(ENV, "iou", out=out, progress=False)
    result = out / "data" / "SYN-02.txt"
    result.write_text(result.read_text()[: 200])  # truncated by hand
    second = run(ENV, "iou", out=out, progress=False)
    assert second.skipped == ["SYN-01"] and "result files" in second.replayed["SYN-02"]
    assert second.combined == pytest.approx(first.combined)


def test_other_agent_options_are_a_different_run_and_a_failed_start_leaves_no_record(
        tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["evaluate", "--env", ENV, "--agent", "iou", "--agent-arg", "min_hits=abc",
                 "--out", str(out), "--quiet"]) == 2
    assert "option 'min_hits' must be int" in capsys.readouterr().err
    assert not out.exists()
    assert main(["evaluate", "--env", ENV, "--agent", "iou", "--agent-arg", "min_hits=2",
                 "--out", str(out), "--quiet"]) == 0


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_out_is_one_clear_line(tmp_path, capsys):  # pragma: no cover - as root
    out = tmp_path / "run"
    out.mkdir()
    out.chmod(0o500)
    assert main(["evaluate", "--env", ENV, "--agent", "iou", "--out", str(out)]) == 2
    assert "cannot write" in capsys.readouterr().err


def test_a_full_disk_keeps_finished_sequences(tmp_path, monkeypatch):
    import errno

    import unitrack_env.benchmarks.motchallenge as mot

    out = tmp_path / "run"
    written = []
    original = mot.atomic_write_text

    def fill_up(path, text):
        if written:
            raise OSError(errno.ENOSPC, "No space left on device")
        written.append(path)
        original(path, text)

    monkeypatch.setattr(mot, "atomic_write_text", fill_up)
    with pytest.raises(OutputError, match="No space left on device"):
        run(ENV, "iou", out=out, progress=False)
    assert [p.name for p in written] == ["SYN-01.txt"]
    assert (out / "sequences" / "SYN-01.json").is_file()
    monkeypatch.setattr(mot, "atomic_write_text", original)
    resumed = run(ENV, "iou", out=out, progress=False)
    assert resumed.skipped == ["SYN-01"]


def _children(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc")
def test_workers_die_with_their_parent(tmp_path):
    script = (
        "import time, numpy as np\n"
        "from unitrack_env.agents import Agent\n"
        "from unitrack_env.evaluation.run.runner import run\n"
        "class Slow(Agent, name='slow-test', tasks=('mot',)):\n"
        "    def reset(self, observation, info): pass\n"
        "    def act(self, observation):\n"
        "        time.sleep(1)\n"
        "        return {'ids': np.zeros(0, int), 'boxes': np.zeros((0, 4))}\n"
        "if __name__ == '__main__':\n"
        f"    run('{ENV}', Slow, out=r'{tmp_path / 'run'}', workers=2, progress=False)\n"
    )
    (tmp_path / "slow.py").write_text(script)
    parent = subprocess.Popen([sys.executable, str(tmp_path / "slow.py")], cwd=tmp_path)
    try:
        deadline = time.monotonic() + 120
        workers: list[int] = []
        while len(workers) < 2 and time.monotonic() < deadline:
            time.sleep(0.5)
            workers = [p for p in _children(parent.pid)
                       if "spawn_main" in (Path("/proc") / str(p) / "cmdline").read_text()]
        assert len(workers) == 2, "the workers did not start"
        os.kill(parent.pid, signal.SIGKILL)  # as the OOM killer would
        parent.wait()
        deadline = time.monotonic() + 20
        while any(map(_alive, workers)) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not any(map(_alive, workers))
        assert not (tmp_path / "run" / "sequences").exists()
    finally:
        if parent.poll() is None:
            parent.kill()


def test_cli_reports_user_errors_in_one_line(tmp_path, capsys):
    cases = {
        ("--env", "UniTrack/MOT16", "--agent", "iou"): "did you mean UniTrack/MOT16-v0",
        ("--env", ENV, "--agent", "no-such-agent"): "unknown agent 'no-such-agent'",
        ("--env", ENV, "--agent", "nope.module:Thing"): "cannot import module 'nope.module'",
        ("--env", ENV, "--agent", "unitrack-vos"): "agents for mot: fresh-ids, iou, unitrack",
        ("--env", ENV, "--agent", "iou", "--env-arg", "colour=red"): "has no option 'colour'",
        ("--env", ENV, "--agent", "iou", "--root", str(tmp_path / "nope")): "is not a folder",
        ("--env", "UniTrack/OTB-v0", "--agent", "repeat-box", "--split", "train"):
            "data_format 'otb' has no option 'split'",
    }
    for args, expected in cases.items():
        code = main(["evaluate", *args, "--out", str(tmp_path / "x"), "--quiet"])
        err = capsys.readouterr().err
        assert code == 2 and expected in err and "Traceback" not in err, (args, err)
    assert not (tmp_path / "x").exists()


def test_an_output_path_through_a_file_is_refused_before_any_work(tmp_path, capsys):
    blocker = tmp_path / "results.csv"
    blocker.write_text("not a folder")
    commands = {
        "evaluate": ["evaluate", "--env", ENV, "--agent", "iou", "--out", str(blocker)],
        "below": ["evaluate", "--env", ENV, "--agent", "iou", "--out", str(blocker / "run")],
        "scorecard": ["scorecard", "--model", "imagenet-lite0", "--tasks", "vos", "--out",
                      str(blocker)],
        "render": ["render", "--env", ENV, "--agent", "iou", "--sequence", "SYN-01", "--out",
                   str(blocker / "video.avi")],
    }
    for what, args in commands.items():
        code = main([*args, "--quiet"] if what != "render" else args)
        err = capsys.readouterr().err
        assert code == 2 and f"{blocker} is a file, not a folder" in err, (what, err)
        assert "Errno" not in err and "Traceback" not in err, (what, err)
    assert blocker.read_text() == "not a folder"


def test_error_text_is_printed_literally(monkeypatch, capsys):
    # rich would read "[nan, 1.0, ...]" as markup and print nothing of it
    from unitrack_env.evaluation.cli import listing

    def boom(args, console):
        raise ValueError("track 1 has a non-finite box [nan, 1.0, 2.0, 3.0]")

    monkeypatch.setattr(listing, "run", boom)
    assert main(["list"]) == 2
    assert "[nan, 1.0, 2.0, 3.0]" in capsys.readouterr().err
