"""Adding a task from a user's project, as docs/adding-a-task.md writes it.

The doc's code blocks titled with a file name (```` ```python title="point_task/env.py" ````)
are written into a project folder outside this repository: a toy point-tracking task with
its environment (the episode template's hooks of a ``SequenceEnv``), its benchmark, its
registration row (:func:`unitrack_env.registration.register_variant`), a trivial agent, a
data script and a script that runs the ``unitrack`` command with the task registered. The
commands of the doc's shell block then run in that folder: ``evaluate`` plays and scores
the task, ``score`` scores the written folder again to the same numbers. Nothing in
unitrack-env is edited.
"""

from __future__ import annotations

import json
import re
import runpy
import shlex
import sys
from pathlib import Path

import gymnasium as gym
import pytest
from gymnasium.utils.env_checker import check_env

from unitrack_env import registration

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "adding-a-task.md"
ENV_ID = "UniTrack/Point-v0"
PROJECT_FILES = {"point_task/__init__.py", "point_task/benchmark.py", "point_task/env.py",
                 "point_task/agent.py", "make_points.py", "point_cli.py"}


def doc_files() -> dict[str, str]:
    """The doc's titled code blocks: file name -> source."""
    return dict(re.findall(r'```python title="([^"]+)"\n(.*?)```', DOC.read_text(), re.S))


def doc_commands() -> list[str]:
    """The commands of the doc's shell block that runs the point task."""
    blocks = re.findall(r"```bash\n(.*?)```", DOC.read_text(), re.S)
    block = next(b for b in blocks if "point_cli.py" in b)
    return [line for line in block.splitlines() if line.strip()]


def run_command(command: str, monkeypatch: pytest.MonkeyPatch, *extra: str) -> None:
    """Run a ``python <script>.py [args]`` line of the doc in this process (exit status 0)."""
    python, script, *args = shlex.split(command)
    assert python == "python", command
    script = str(Path(script).resolve())  # as `python x.py` gives it: a child process finds it
    monkeypatch.setattr(sys, "argv", [script, *args, *extra])
    try:
        runpy.run_path(script, run_name="__main__")
    except SystemExit as exc:
        assert exc.code in (0, None), f"{command}: exit status {exc.code}"


@pytest.fixture
def project(tmp_path, monkeypatch):
    """The doc's project in a temporary folder (the current folder, on ``sys.path``), its
    data written by the doc's script and its row registered; all undone afterwards."""
    folder = tmp_path / "project"
    files = doc_files()
    assert PROJECT_FILES <= set(files), sorted(files)
    for name in PROJECT_FILES:
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(files[name])
    monkeypatch.chdir(folder)
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.setattr(registration, "_ADDED", [])
    commands = doc_commands()
    assert commands[0] == "python make_points.py"
    run_command(commands[0], monkeypatch)
    import point_task  # noqa: F401 - registers the row

    yield folder / "data"
    gym.registry.pop(ENV_ID, None)
    for name in [m for m in sys.modules if m == "point_task" or m.startswith("point_task.")]:
        del sys.modules[name]


def test_a_new_task_runs_through_evaluate_and_score(project, monkeypatch, capsys):
    evaluate, score = doc_commands()[1:]
    assert " evaluate " in evaluate and " score " in score
    capsys.readouterr()
    run_command(evaluate, monkeypatch, "--format", "json")
    evaluated = json.loads(capsys.readouterr().out)
    out = Path(shlex.split(evaluate)[shlex.split(evaluate).index("--out") + 1])
    assert sorted(p.name for p in (out / "data").iterdir()) == ["dot-1.txt", "dot-2.txt"]
    assert set(evaluated["combined"]) == {"MeanError", "Success@5px"}
    assert 0.0 < evaluated["combined"]["MeanError"] < 10.0

    run_command(score, monkeypatch, "--format", "json")
    assert json.loads(capsys.readouterr().out) == evaluated

    run_command(score, monkeypatch)
    table = capsys.readouterr().out
    assert "Success@5px" in table and "dot-2" in table


def test_the_row_names_its_benchmark_and_ids_do_not_clash(project):
    from unitrack_env.benchmarks import benchmark_for, task_columns

    assert ENV_ID in registration.env_ids("point")
    assert task_columns("point") == ("Success@5px", "MeanError")
    assert benchmark_for(ENV_ID, root=str(project)).sequence_names == ["dot-1", "dot-2"]
    row = registration.variant(ENV_ID)
    registration.register_variant(row)  # the same row again: nothing happens
    with pytest.raises(ValueError, match="already registered"):
        registration.register_variant(registration.Variant("Point", "elsewhere:Env"))


@pytest.mark.filterwarnings("ignore:.*symmetric and normalized space")  # a point in pixels
def test_the_toy_env_keeps_the_gymnasium_contract(project):
    env = gym.make(ENV_ID, root=str(project))
    check_env(env.unwrapped, skip_render_check=True)
    observation, info = env.reset(options={"sequence": "dot-2"})
    assert info["task"] == "point" and info["seq_length"] == 12
    terminated = False
    while not terminated:
        observation, reward, terminated, _, info = env.step(observation["point"])
    assert set(info["metrics"]) == {"MeanError", "Success@5px"}
    env.reset()
    with pytest.raises(ValueError, match="finite"):
        env.step([float("nan"), 0.0])
    env.close()
