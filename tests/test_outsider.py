"""A user's first hour, from a wheel, next to other packages (marked ``install``; CI runs it).

In a fresh virtual environment: ``openai-agents`` (which ships a top-level ``agents``
package) goes in first; then unitrack-env's wheel, first with a plain ``pip install`` (no
TrackEval: a MOT run must refuse to start and name the fix), then by the README's setup
script. From a project folder that has its own ``agents/`` and ``evaluation/`` packages and a
conftest: the README quickstart runs, the project's pytest passes an ``episode_regression``
golden test of its own agent (docs/regression-tests.md's example), docs/writing-an-agent.md's
agent runs by reference, and ``unitrack evaluate --agent my_tracker:MyTracker --workers 2``
survives a Ctrl-C and resumes to the same metrics as an uninterrupted run.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.install

MY_AGENTS = '''
import time

from unitrack_env.agents import Agent
from unitrack_env.spaces import pack_tracks, unpack_detections


class MyTracker(Agent, name="my-tracker", tasks=("mot",)):
    """Every detection above threshold gets the id of the previous box it overlaps most."""

    def __init__(self, threshold: float = 0.0, delay: float = 0.0, slow: str = ""):
        self.threshold, self.delay, self.slow = threshold, delay, slow

    def reset(self, observation, info):
        self.next_id, self.previous = 1, []
        self.pause = self.delay if info["sequence"] == self.slow or not self.slow else 0.0

    def act(self, observation):
        time.sleep(self.pause)
        boxes, scores = unpack_detections(observation)
        boxes = boxes[scores >= self.threshold]
        ids = []
        for box in boxes:
            best, best_iou = None, 0.3
            for track_id, old in self.previous:
                x1, y1 = max(box[0], old[0]), max(box[1], old[1])
                x2 = min(box[0] + box[2], old[0] + old[2])
                y2 = min(box[1] + box[3], old[1] + old[3])
                inter = max(0.0, x2 - x1) * max(0.0, y2 - y1)
                iou = inter / (box[2] * box[3] + old[2] * old[3] - inter)
                if iou > best_iou and track_id not in ids:
                    best, best_iou = track_id, iou
            if best is None:
                best, self.next_id = self.next_id, self.next_id + 1
            ids.append(best)
        self.previous = list(zip(ids, boxes))
        return pack_tracks(ids, boxes, 512)
'''

def _doc_blocks(name: str) -> list[str]:
    """The Python examples of a documentation page, as written."""
    return re.findall(r"```python\n(.*?)```", (REPO / "docs" / name).read_text(), re.S)


def _run(args: list[str], cwd: Path, env: dict[str, str], timeout: float = 900,
         check: bool = True) -> subprocess.CompletedProcess:
    result = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True,
                            timeout=timeout)
    if check and result.returncode != 0:
        raise AssertionError(f"{' '.join(args)} exited {result.returncode}\n"
                             f"stdout:\n{result.stdout[-3000:]}\nstderr:\n{result.stderr[-3000:]}")
    return result


@pytest.fixture(scope="module")
def outsider(tmp_path_factory: pytest.TempPathFactory) -> dict:
    base = tmp_path_factory.mktemp("outsider")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("UNITRACK_", "VIRTUAL_ENV",
                                                                     "PYTHON"))}
    env["UNITRACK_CACHE"] = str(base / "cache")
    dist = base / "dist"
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(dist),
          str(REPO)], REPO, env)
    wheel = next(dist.glob("unitrack_env-*.whl"))
    venv = base / "venv"
    _run([sys.executable, "-m", "venv", str(venv)], base, env)
    python = venv / "bin" / "python"
    pip = [str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check"]
    _run([*pip, "openai-agents", "torch==2.13.0", "pytest"], base, env)
    _run([*pip, str(wheel)], base, env)
    project = base / "project"
    for package in ("agents", "evaluation"):
        (project / package).mkdir(parents=True)
        (project / package / "__init__.py").write_text(f'"""The user\'s own {package}."""\n')
    (project / "conftest.py").write_text('"""The user\'s conftest."""\n')
    (project / "pytest.ini").write_text("[pytest]\npythonpath = .\n")
    (project / "my_tracker.py").write_text(MY_AGENTS)
    (project / "nearest.py").write_text(_doc_blocks("writing-an-agent.md")[0])
    (project / "agents" / "nearest.py").write_text(_doc_blocks("writing-an-agent.md")[0])
    (project / "tests").mkdir()
    (project / "tests" / "test_my_tracker.py").write_text(_doc_blocks("regression-tests.md")[0])
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    return {"base": base, "env": env, "python": python, "project": project, "wheel": wheel,
            "venv": venv, "unitrack": str(venv / "bin" / "unitrack")}


def test_plain_pip_install_refuses_before_the_first_frame(outsider):
    result = _run([outsider["unitrack"], "evaluate", "--env", "UniTrack/MOT16-v0", "--agent",
                   "iou", "--out", "no-trackeval"], outsider["project"], outsider["env"],
                  check=False)
    assert result.returncode == 2
    assert "pip install --no-deps trackeval==1.3.0" in result.stderr
    assert "Traceback" not in result.stderr
    assert not (outsider["project"] / "no-trackeval" / "data").exists()


def test_readme_install_then_quickstart_pytest_and_cli(outsider):
    project, env = outsider["project"], outsider["env"]
    setup = _run(["bash", str(REPO / "scripts" / "setup.sh")], REPO,
                 env | {"UNITRACK_VENV": str(outsider["venv"]),
                        "UNITRACK_WHEEL": str(outsider["wheel"])})
    assert "ERROR" not in setup.stderr and "conflicts" not in setup.stderr  # issue 42
    readme = (REPO / "README.md").read_text()
    quickstart = re.findall(r"```python\n(.*?)```", readme, re.S)[0]
    (project / "quickstart.py").write_text(quickstart)
    printed = _run([str(outsider["python"]), "quickstart.py"], project, env).stdout.split()
    assert len(printed) == 3 and all(0 <= float(x) <= 1 for x in printed)

    # docs/regression-tests.md's example, recorded from the project, checked from tests/
    tests = [str(outsider["python"]), "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rs"]
    _run([*tests, "--update-goldens"], project, env)
    golden = project / "tests" / "goldens" / "my-tracker-SYN-01.json"
    assert golden.is_file() and golden.stat().st_mode & 0o044  # the umask's mode, not 0600
    result = _run(tests, project / "tests", env)
    assert "1 passed, 1 skipped" in result.stdout and "no data for" in result.stdout
    record = json.loads(golden.read_text())
    record["metrics"]["HOTA"] += 0.01
    golden.write_text(json.dumps(record))
    failed = _run(tests, project, env, check=False)
    assert failed.returncode == 1 and "HOTA" in failed.stdout
    assert "site-packages" not in failed.stdout  # the diff, not a library traceback

    # docs/writing-an-agent.md's example and commands, as written
    _run([outsider["unitrack"], "evaluate", "--env", "UniTrack/MOT16-v0", "--agent",
          "nearest:NearestCentre", "--out", "runs/nc"], project, env)
    _run([outsider["unitrack"], "evaluate", "--env", "UniTrack/MOT16-v0", "--agent",
          "nearest.py:NearestCentre", "--agent-arg", "max_distance=80", "--workers", "2",
          "--out", "runs/nc80"], project, env)
    # The project's own agents/ package, though openai-agents installed a top-level agents
    _run([outsider["unitrack"], "evaluate", "--env", "UniTrack/MOT16-v0", "--agent",
          "agents.nearest:NearestCentre", "--quiet", "--out", "runs/nc-own"], project, env)
    combined = [json.loads((project / "runs" / run / "metrics.json").read_text())["combined"]
                for run in ("nc", "nc-own")]
    assert combined[0] == combined[1]

    evaluate = [outsider["unitrack"], "evaluate", "--env", "UniTrack/MOT17-v0", "--agent",
                "my_tracker:MyTracker", "--quiet", "--format", "json"]
    reference = _run([*evaluate, "--out", "ref"], project, env)
    # SYN-01 is played at 0.2 s a frame (72 frames, ~14 s), SYN-02 at full speed: SYN-02 is
    # kept and SYN-01 is interrupted however far apart the two workers start.
    slow = [*evaluate, "--agent-arg", "delay=0.2", "--agent-arg", "slow=SYN-01", "--workers",
            "2", "--out", "run"]
    # As from a terminal: SIGINT at its default even when these tests run in a background job
    # (bash starts those with SIGINT ignored, and Python keeps an ignored SIGINT ignored).
    process = subprocess.Popen(slow, cwd=project, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, start_new_session=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    records = project / "run" / "sequences"
    deadline = time.monotonic() + 300
    while not (records.is_dir() and any(records.iterdir())) and time.monotonic() < deadline:
        time.sleep(0.2)
    os.killpg(process.pid, signal.SIGINT)  # Ctrl-C reaches the whole process group
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    kept = sorted(p.stem for p in records.iterdir())
    assert kept == ["SYN-02"]
    resumed = _run(slow, project, env)
    assert f"resumed: kept {len(kept)}" in resumed.stderr
    assert json.loads(resumed.stdout) == json.loads(reference.stdout)


def test_pytest_of_a_project_with_its_own_evaluation_package_loads_our_plugin(outsider):
    result = _run([str(outsider["python"]), "-m", "pytest", "--co", "-q", "-p",
                   "no:cacheprovider"], outsider["project"], outsider["env"])
    assert "test_my_tracker_on_synthetic" in result.stdout
    check = _run([str(outsider["python"]), "-c", textwrap.dedent("""
        import agents, evaluation, unitrack_env.agents as ua
        print(agents.__file__, evaluation.__file__, ua.make_agent("iou").name)
    """)], outsider["project"], outsider["env"])
    own, evaluation, name = check.stdout.split()
    assert own.startswith(str(outsider["project"])) and name == "iou"
    assert evaluation.startswith(str(outsider["project"]))
