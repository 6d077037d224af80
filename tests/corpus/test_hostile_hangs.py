"""Hostile agents through the CLI: every hang ends and every crash is named (issue 43, item 5).

Each case runs ``unitrack evaluate`` in a subprocess with a hard timeout, so that a regression
fails here instead of hanging CI. docs/bad-inputs.md ("Hostile agents: hangs and crashes")
lists the cases with their messages.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")

ENV = "UniTrack/MOT16-v0"  # two synthetic sequences: SYN-01 misbehaves, SYN-02 must be kept
#: Seconds a case may take at most before it counts as a hang (the runs take a few seconds).
HARD_TIMEOUT = 120

AGENT = """
import ctypes, itertools, os, re, time
from unitrack_env.agents.baselines.iou import IoUAgent

class Hostile(IoUAgent):
    def reset(self, observation, info):
        self.sequence, self.frames = info["sequence"], 0
        return super().reset(observation, info)

    def act(self, observation):
        self.frames += 1
        mark = os.environ.get("HOSTILE_MARK")
        if mark:
            open(f"{{mark}}.{{os.getpid()}}", "w").close()
        if self.sequence == "SYN-01" and self.frames == 3:
            {act}
        return super().act(observation)

    def close(self):
        {close}
"""

#: A catastrophic regex: C code holding the GIL for hours (it checks for signals).
REGEX = "re.match(r'(a+)+$', 'a' * 40 + 'b')"
#: A C loop that holds the GIL and never checks for signals (only another process stops it).
NATIVE = "sum(itertools.repeat(1, 10 ** 13))"
SEGFAULT = "ctypes.string_at(0)"


def _agent(tmp_path: Path, act: str = "pass", close: str = "pass") -> str:
    path = tmp_path / "hostile_agent.py"
    path.write_text(AGENT.format(act=act, close=close))
    return f"{path}:Hostile"


def _command(tmp_path: Path, agent: str, *extra: str) -> list[str]:
    return [sys.executable, "-m", "unitrack_env.evaluation.cli", "evaluate", "--env", ENV,
            "--agent", agent, "--out", str(tmp_path / "run"), "--quiet", *extra]


def _environ(**extra: str) -> dict[str, str]:
    return os.environ | {"PYTHONPATH": os.pathsep.join(sys.path)} | extra


def _evaluate(tmp_path: Path, agent: str, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(_command(tmp_path, agent, *extra), capture_output=True, text=True,
                          timeout=HARD_TIMEOUT, env=_environ())


def _kept(tmp_path: Path, *names: str) -> bool:
    return all((tmp_path / "run" / "sequences" / f"{name}.json").is_file() for name in names)


@pytest.mark.parametrize("act", [REGEX, NATIVE], ids=["regex", "native-loop"])
def test_a_step_stuck_in_c_code_fails_its_sequence_and_the_run_goes_on(tmp_path, act):
    done = _evaluate(tmp_path, _agent(tmp_path, act=act), "--step-timeout", "2")
    assert done.returncode == 1, done.stderr
    assert "SYN-01: no step finished within 2 s (after frame 2)" in done.stderr
    assert "Traceback" not in done.stderr
    assert _kept(tmp_path, "SYN-02")  # the next sequence played


def test_a_close_that_never_returns_is_stopped_and_named(tmp_path):
    done = _evaluate(tmp_path, _agent(tmp_path, close=NATIVE), "--step-timeout", "2")
    assert done.returncode == 0, done.stderr
    assert "close() did not return within 2 s" in done.stderr
    assert (tmp_path / "run" / "metrics.json").is_file()  # scored: the results are kept
    assert _kept(tmp_path, "SYN-01", "SYN-02")


def test_a_segfault_in_this_process_fails_its_sequence_with_the_signal_named(tmp_path):
    done = _evaluate(tmp_path, _agent(tmp_path, act=SEGFAULT))
    assert done.returncode == 1, (done.returncode, done.stderr)
    assert "SYN-01: " in done.stderr and "SIGSEGV" in done.stderr
    assert _kept(tmp_path, "SYN-02")


@pytest.mark.parametrize("trial", range(3))
def test_sigterm_during_a_run_in_workers_ends_with_one_line(tmp_path, trial):
    mark = tmp_path / "playing"
    process = subprocess.Popen(_command(tmp_path, _agent(tmp_path, act="time.sleep(0.05)"),
                                        "--workers", "2"),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env=_environ(HOSTILE_MARK=str(mark)))
    try:
        started = time.monotonic()
        while len(list(tmp_path.glob("playing.*"))) < 2:  # both workers are in act()
            assert process.poll() is None, process.communicate()
            assert time.monotonic() - started < HARD_TIMEOUT, "the workers never started"
            time.sleep(0.05)
        time.sleep(0.1 * trial)
        process.send_signal(signal.SIGTERM)
        # Wait for the workers too: they hold the pipes open until they are gone.
        _, stderr = process.communicate(timeout=HARD_TIMEOUT)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 128 + signal.SIGTERM, stderr
    assert "Traceback" not in stderr and "Error" not in stderr, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("terminated"), stderr
    assert (tmp_path / "run" / "run.json").is_file()
