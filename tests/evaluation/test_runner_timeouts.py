"""Hung and crashing agents: a step limit, and a dead worker blamed for its own sequence only."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from unitrack_env.evaluation.run.pool import CLOSING, SupervisedPool, WorkerTimedOut, describe_exit
from unitrack_env.evaluation.run.runner import RunFailed, run
from unitrack_env.evaluation.run.watchdog import Terminated, sigterm_stops
from unitrack_env.evaluation.run.workers import init_worker

ENV = "UniTrack/MOT16-v0"

#: An IoU agent that misbehaves on one sequence: ``HOW`` on ``BAD`` at frame 3.
AGENT = """
import os, signal, time
from unitrack_env.agents.baselines.iou import IoUAgent

class Bad(IoUAgent):
    def reset(self, observation, info):
        self.sequence, self.frames = info["sequence"], 0
        return super().reset(observation, info)

    def act(self, observation):
        self.frames += 1
        if self.sequence == {bad!r} and self.frames == 3:
            {how}
        return super().act(observation)
"""

HANG = "time.sleep(3600)"
SEGFAULT = "os.kill(os.getpid(), signal.SIGSEGV)"
OOM = "os.kill(os.getpid(), signal.SIGKILL)"
SWALLOW = "\n            ".join([  # an agent that catches every Exception around a hang
    "try:", "    time.sleep(3600)", "except Exception:", "    pass"])


def _agent(tmp_path: Path, how: str, bad: str = "SYN-01") -> str:
    path = tmp_path / "bad_agent.py"
    path.write_text(AGENT.format(bad=bad, how=how))
    return f"{path}:Bad"


@pytest.mark.parametrize("how", [HANG, SWALLOW])
def test_a_hung_agent_fails_its_sequence_in_this_process(tmp_path, how):
    out = tmp_path / "run"
    with pytest.raises(RunFailed) as caught:
        run(ENV, _agent(tmp_path, how), out=out, progress=False, step_timeout=1)
    assert list(caught.value.failures) == ["SYN-01"]
    assert "no step finished within 1 s (after frame 2)" in caught.value.failures["SYN-01"]
    assert (out / "sequences" / "SYN-02.json").is_file()  # the next sequence still played


@pytest.mark.slow  # worker start-up; the corpus's CLI-worker-segfault covers the pool in CI
def test_a_hung_agent_fails_its_sequence_in_a_worker(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(RunFailed) as caught:
        run(ENV, _agent(tmp_path, HANG), out=out, progress=False, workers=2, step_timeout=2)
    assert list(caught.value.failures) == ["SYN-01"]
    assert "no step finished within 2 s" in caught.value.failures["SYN-01"]
    assert "worker process was stopped" in caught.value.failures["SYN-01"]
    assert (out / "sequences" / "SYN-02.json").is_file()


@pytest.mark.parametrize(("how", "named", "bad", "good"), [
    pytest.param(SEGFAULT, "SIGSEGV", "SYN-02", "SYN-01", marks=pytest.mark.slow),  # in corpus
    pytest.param(OOM, "SIGKILL", "SYN-01", "SYN-02", marks=pytest.mark.slow),
])
def test_a_crashed_worker_blames_only_its_sequence_and_names_the_signal(tmp_path, how, named,
                                                                         bad, good):
    out = tmp_path / "run"  # two workers: the other sequence is in flight when one crashes
    with pytest.raises(RunFailed) as caught:
        run(ENV, _agent(tmp_path, how, bad), out=out, progress=False, workers=2)
    assert list(caught.value.failures) == [bad], caught.value.failures
    assert named in caught.value.failures[bad]
    assert (out / "sequences" / f"{good}.json").is_file()


def test_exit_descriptions_name_the_signal():
    assert "SIGSEGV" in describe_exit(-11) and "native code" in describe_exit(-11)
    assert "SIGKILL" in describe_exit(-9) and "out-of-memory" in describe_exit(-9)
    assert "status 3" in describe_exit(3)


def test_no_limit_lets_a_slow_step_finish(tmp_path):
    agent = _agent(tmp_path, "time.sleep(1.5)")
    report = run(ENV, agent, out=tmp_path / "run", progress=False, step_timeout=0)
    assert sorted(report.records) == ["SYN-01", "SYN-02"]


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_step_that_cannot_be_interrupted_ends_the_process_with_a_line(tmp_path):
    # SIGALRM blocked in the agent's call: like a C call that never returns to Python.
    how = ("signal.pthread_sigmask(signal.SIG_BLOCK, [signal.SIGALRM]); time.sleep(3600)")
    agent = _agent(tmp_path, how, bad="SYN-02")
    script = textwrap.dedent(f"""
        import unitrack_env.evaluation.run.watchdog as watchdog
        from unitrack_env.evaluation.run.runner import run
        watchdog.GRACE = 1
        run({ENV!r}, {agent!r}, out={str(tmp_path / 'run')!r}, progress=False,
            step_timeout=1)
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, env=os.environ | {"PYTHONPATH": os.pathsep.join(
                              sys.path)})
    assert done.returncode == 3, done.stderr
    assert "sequence 'SYN-02': no step finished within 1 s" in done.stderr
    assert "--workers 2" in done.stderr
    assert (tmp_path / "run" / "sequences" / "SYN-01.json").is_file()  # kept


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_step_in_c_code_holding_the_gil_is_stopped_in_this_process(tmp_path):
    # A catastrophic regex holds the GIL (a watchdog thread could never run) but checks for
    # signals: the kernel timer's SIGALRM stops it on time, and the next sequence plays.
    agent = _agent(tmp_path, "import re; re.match(r'(a+)+$', 'a' * 40 + 'b')")
    script = textwrap.dedent(f"""
        from unitrack_env.evaluation.run.runner import RunFailed, run
        try:
            run({ENV!r}, {agent!r}, out={str(tmp_path / 'run')!r}, progress=False,
                step_timeout=1)
        except RunFailed as failed:
            print(failed.failures["SYN-01"])
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, env=os.environ | {"PYTHONPATH": os.pathsep.join(
                              sys.path)})  # a hard limit: a regression fails, never hangs
    assert "no step finished within 1 s (after frame 2)" in done.stdout, done.stderr
    assert (tmp_path / "run" / "sequences" / "SYN-02.json").is_file()


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_sigterm_inside_the_block_stops_like_ctrl_c():
    with pytest.raises(Terminated), sigterm_stops():
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # restored


def test_an_isolated_run_keeps_the_in_process_results(tmp_path):
    here = run(ENV, "iou", out=tmp_path / "here", progress=False)
    child = run(ENV, "iou", out=tmp_path / "child", progress=False, isolate=True)
    for name in ("SYN-01", "SYN-02"):
        assert ((tmp_path / "here" / "data" / f"{name}.txt").read_bytes()
                == (tmp_path / "child" / "data" / f"{name}.txt").read_bytes())
        assert here.records[name].digest == child.records[name].digest
    assert here.combined == child.combined


def _saved_then_hung_in_close(item: int, beat) -> None:
    """A pool task whose work is saved and whose agent's close() never returns."""
    beat(0)
    beat(CLOSING)
    time.sleep(3600)


def test_a_worker_stuck_in_close_is_stopped_and_named():
    with SupervisedPool(1, 0, step_timeout=1, init=init_worker) as pool:
        [(item, outcome)] = list(pool.run(_saved_then_hung_in_close, [7], lambda i: (i,)))
    assert item == 7 and isinstance(outcome, WorkerTimedOut)
    assert "close() did not return within 1 s after the sequence was saved" in str(outcome)
