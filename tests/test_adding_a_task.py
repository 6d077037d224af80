"""Adding a task, and a data format, from a user's project, as docs/adding-a-task.md writes it.

The doc's code blocks titled with a file name (```` ```python title="centroid_task/env.py" ````)
are written into a project folder outside this repository: a toy centroid-tracking task
with its environment (the episode template's hooks of a ``SequenceEnv``), its benchmark
(which also answers events, intervals, the report and the scorecard column), its
registration row (:func:`unitrack_env.registration.register_variant`), two trivial agents, a
data script and a script that runs the ``unitrack`` command with the task registered. The
commands of the doc's shell block then run in that folder: ``evaluate``, ``score``,
``events``, ``compare``, ``report`` and ``scorecard``. Nothing in unitrack-env is edited.
The doc's data-format example adds a LaSOT-layout id beside OTB through ``SOT_FORMATS``.
"""

from __future__ import annotations

import json
import re
import runpy
import shlex
import sys
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from unitrack_env import registration

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "adding-a-task.md"
ENV_ID = "UniTrack/Centroid-v0"
PROJECT_FILES = {"centroid_task/__init__.py", "centroid_task/benchmark.py",
                 "centroid_task/env.py", "centroid_task/agent.py", "make_centroids.py",
                 "centroid_cli.py"}


def doc_files() -> dict[str, str]:
    """The doc's titled code blocks: file name -> source."""
    return dict(re.findall(r'```python title="([^"]+)"\n(.*?)```', DOC.read_text(), re.S))


def doc_commands() -> dict[str, str]:
    """The commands of the doc's shell block that runs the task, by ``unitrack`` command
    (the data script as ``"data"``; the two evaluations as ``evaluate`` and ``evaluate-2``)."""
    blocks = re.findall(r"```bash\n(.*?)```", DOC.read_text(), re.S)
    block = next(b for b in blocks if "centroid_cli.py" in b)
    out: dict[str, str] = {}
    for line in filter(str.strip, block.splitlines()):
        words = shlex.split(line)
        name = words[2] if len(words) > 2 else "data"
        out[name if name not in out else f"{name}-2"] = line
    return out


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
    assert commands["data"] == "python make_centroids.py"
    run_command(commands["data"], monkeypatch)
    import centroid_task  # noqa: F401 - registers the row

    yield folder / "data" / "Centroid"
    gym.registry.pop(ENV_ID, None)
    for name in [m for m in sys.modules if m == "centroid_task" or m.startswith("centroid_task.")]:
        del sys.modules[name]


def test_a_new_task_runs_through_every_command(project, monkeypatch, capsys):
    """evaluate and score; then events, compare, the report and the scorecard's plan, all
    from the task's benchmark (the scorecard command itself: the slow test below)."""
    commands = doc_commands()
    capsys.readouterr()
    run_command(commands["evaluate"], monkeypatch, "--format", "json")
    evaluated = json.loads(capsys.readouterr().out)
    out = Path("runs/echo")
    assert sorted(p.name for p in (out / "data").iterdir()) == ["blob-1.txt", "blob-2.txt"]
    assert set(evaluated["combined"]) == {"MeanError", "Success@5px"}
    assert evaluated["per_sequence"]["blob-1"]["MeanError"] == pytest.approx(3.977, abs=1e-3)

    run_command(commands["score"], monkeypatch, "--format", "json")
    assert json.loads(capsys.readouterr().out) == evaluated
    run_command(commands["score"], monkeypatch)
    table = capsys.readouterr().out
    assert "Success@5px" in table and "blob-2" in table

    run_command(commands["evaluate-2"], monkeypatch)
    capsys.readouterr()
    run_command(commands["events"], monkeypatch, "--format", "csv")
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1 + 12 and all(",blob-1," in f",{line}" for line in lines[1:])

    run_command(commands["compare"], monkeypatch, "--format", "json")
    compared = json.loads(capsys.readouterr().out)
    smooth = json.loads(Path("runs/smooth/metrics.json").read_text())["combined"]
    row = compared["rows"]["COMBINED"]
    assert set(row) == {"Success@5px", "MeanError"}
    assert row["MeanError"]["a"] == pytest.approx(smooth["MeanError"], abs=1e-4)  # events: 4 dp
    assert any("too little data" in note for note in compared["notes"])

    run_command(commands["report"], monkeypatch)
    page = Path("report/index.html").read_text()
    assert 'id="compare"' in page and "error (px)" in page and "No per-frame events" not in page

    from unitrack_env.evaluation.scorecard.plan import TASKS, ModelSpec, plan

    cells, sources, _ = plan([ModelSpec.parse("random")], ["centroid"], Path("data"))
    assert TASKS["centroid"].title == "Centroid" and sources["centroid"].kind == "benchmark"
    assert {(c.head, c.sequence) for c in cells} == {
        (head, seq) for head in ("smooth", "echo") for seq in ("blob-1", "blob-2")}


@pytest.mark.slow  # loads an appearance model (torch) and draws the radar chart
def test_the_scorecard_command_gives_the_task_a_column(project, monkeypatch):
    commands = doc_commands()
    run_command(commands["evaluate-2"], monkeypatch)
    smooth = json.loads(Path("runs/smooth/metrics.json").read_text())["combined"]
    run_command(commands["scorecard"], monkeypatch, "--workers", "1")
    card = json.loads(Path("card/scorecard.json").read_text())
    assert card["tasks"] == ["centroid"]
    heads = {(row["model"], row["head"]): row["combined"] for row in card["rows"]}
    assert heads[("random", "smooth")] == pytest.approx(smooth)
    table = Path("card/scorecard.md").read_text()
    assert "Centroid MeanError ↓" in table and "Centroid Success@5px ↑" in table


def test_the_row_names_its_benchmark_and_ids_do_not_clash(project):
    from unitrack_env.benchmarks import benchmark_for, task_columns

    assert ENV_ID in registration.env_ids("centroid")
    assert task_columns("centroid") == ("Success@5px", "MeanError")
    assert benchmark_for(ENV_ID, root=str(project)).sequence_names == ["blob-1", "blob-2"]
    row = registration.variant(ENV_ID)
    registration.register_variant(row)  # the same row again: nothing happens
    with pytest.raises(ValueError, match="already registered"):
        registration.register_variant(registration.Variant("Centroid", "elsewhere:Env"))


@pytest.mark.filterwarnings("ignore:.*symmetric and normalized space")  # a centre in pixels
def test_the_toy_env_keeps_the_gymnasium_contract(project):
    env = gym.make(ENV_ID, root=str(project))
    check_env(env.unwrapped, skip_render_check=True)
    observation, info = env.reset(options={"sequence": "blob-2"})
    assert info["task"] == "centroid" and info["seq_length"] == 12
    terminated = False
    while not terminated:
        observation, reward, terminated, _, info = env.step(observation["centroid"])
    assert set(info["metrics"]) == {"MeanError", "Success@5px"}
    env.reset()
    with pytest.raises(ValueError, match="finite"):
        env.step([float("nan"), 0.0])
    env.close()


def _lasot_folder(root: Path) -> Path:
    """A two-sequence LaSOT-layout folder (``<class>/<class>-<n>/img``, ``groundtruth.txt``)."""
    for k in (1, 2):
        seq = root / "blob" / f"blob-{k}"
        (seq / "img").mkdir(parents=True)
        rows = []
        for t in range(6):
            image = np.zeros((48, 64, 3), np.uint8)
            x, y = 10 + 3 * t, 8 + k * t
            image[y:y + 12, x:x + 10] = 255
            cv2.imwrite(str(seq / "img" / f"{t + 1:08d}.jpg"), image)
            rows.append(f"{x},{y},10,12")
        (seq / "groundtruth.txt").write_text("\n".join(rows) + "\n")
    return root


def test_a_sot_data_format_is_a_reader_a_format_row_and_a_registration_row(
        tmp_path, monkeypatch):
    from unitrack_env.benchmarks import benchmark_for
    from unitrack_env.benchmarks import otb as otb_benchmark
    from unitrack_env.evaluation.analysis.events import load_events
    from unitrack_env.evaluation.run.runner import run

    example = next(b for b in re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)
                   if "SOT_FORMATS" in b)
    monkeypatch.setattr(registration, "_ADDED", [])
    monkeypatch.setattr(otb_benchmark, "SOT_FORMATS", dict(otb_benchmark.SOT_FORMATS))
    monkeypatch.delenv("UNITRACK_DATA", raising=False)
    exec(compile(example, str(DOC), "exec"), {})  # noqa: S102 - the doc's own example
    try:
        root = _lasot_folder(tmp_path / "MyLaSOT")
        report = run("UniTrack/MyLaSOT-v0", "repeat-box", out=tmp_path / "run",
                     env_kwargs={"root": str(root)}, progress=False)
        assert sorted(report.records) == ["blob-1", "blob-2"]
        assert report.scores.combined["AUC"] > 0
        assert len(load_events(tmp_path / "run", sequence="blob-1")) == 6
        default = benchmark_for("UniTrack/MyLaSOT-v0")  # no data: the task's synthetic data
        assert default.synthetic and default.name == "MyLaSOT" and default.sequence_names
    finally:
        gym.registry.pop("UniTrack/MyLaSOT-v0", None)
