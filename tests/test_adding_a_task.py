"""Adding a task from a user's project: one env module, one benchmark module, one table row.

A project folder outside this repository defines a toy point-tracking task (follow one point
through noisy measurements of it): ``point_task/env.py`` (the environment: the episode
template's hooks of a ``SequenceEnv``), ``point_task/benchmark.py`` (its
:class:`~unitrack_env.benchmarks.Benchmark`: ground truth, result files, scoring, columns),
the registration row in ``point_task/__init__.py``
(:func:`unitrack_env.registration.register_variant`) and a trivial agent. Nothing in
unitrack-env is edited; ``unitrack evaluate`` plays and scores the task, and ``unitrack
score`` scores the written folder again to the same numbers.
"""

from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import pytest

from unitrack_env import registration
from unitrack_env.evaluation.cli import main

ENV_ID = "UniTrack/Point-v0"

INIT = '''
"""A toy point-tracking task: its registration row."""

from unitrack_env.registration import Variant, register_variant

register_variant(Variant("Point", "point_task.env:PointEnv", {}, "point",
                         scoring="point_task.benchmark:PointBenchmark"))
'''

BENCHMARK = '''
"""Point tracking's benchmark: ground truth, ``x,y`` result files, mean error, success."""

import json
from pathlib import Path

import numpy as np

from unitrack_env.benchmarks.base import Benchmark, rounded_digest
from unitrack_env.io import atomic_write_text
from unitrack_env.metrics.report import COMBINED, ScoreReport


class PointSequence:
    """One sequence: its name, true points and measured points, ``(frames, 2)`` each."""

    def __init__(self, name, truth, measured):
        self.name = name
        self.truth = np.asarray(truth, dtype=np.float64)
        self.measured = np.asarray(measured, dtype=np.float64)


class PointData:
    """``<root>/points.json``: ``{sequence: {"truth": [[x, y], ...], "measured": [...]}}``."""

    def __init__(self, root):
        self.root = Path(root)
        self.sequences = json.loads((self.root / "points.json").read_text())
        self.sequence_names = sorted(self.sequences)

    def sequence(self, name):
        return PointSequence(name, **self.sequences[name])


def point_metrics(predicted, truth):
    error = np.linalg.norm(predicted - truth, axis=1)
    return {"MeanError": float(error.mean()), "Success@5px": float((error <= 5).mean())}


class PointBenchmark(Benchmark):
    """Results of one sequence: ``(frames, 2)`` points, one ``x,y`` line per frame."""

    task = "point"
    columns = ("Success@5px", "MeanError")

    @classmethod
    def from_kwargs(cls, root=None, **_):
        if root is None:
            raise ValueError("the point task needs root= (a folder with points.json)")
        return cls(PointData(root))

    @property
    def name(self):
        return "Points"

    def sequence_length(self, name):
        return len(self.dataset.sequences[name]["truth"])

    def has_ground_truth(self, name):
        return True

    def write(self, folder, sequence, results):
        lines = [f"{x:.3f},{y:.3f}" for x, y in results]
        atomic_write_text(Path(folder) / f"{sequence}.txt", "\\n".join(lines) + "\\n")

    def read(self, folder, sequence):
        return np.loadtxt(Path(folder) / f"{sequence}.txt", delimiter=",", ndmin=2)

    def digest(self, results):
        return rounded_digest(results)

    def score_sequence(self, sequence, results):
        return point_metrics(results, self.dataset.sequence(sequence).truth)

    def score_folder(self, folder, sequences):
        per_sequence = {name: self.score_sequence(name, self.read(folder, name))
                        for name in sequences}
        predicted = np.concatenate([self.read(folder, name) for name in sequences])
        truth = np.concatenate([self.dataset.sequence(name).truth for name in sequences])
        combined = point_metrics(predicted, truth)
        return ScoreReport(self.name, per_sequence, combined,
                           {**per_sequence, COMBINED: combined})
'''

ENV = '''
"""Point tracking: follow one point through noisy measurements of it."""

from pathlib import Path

import numpy as np
from gymnasium import spaces

from point_task.benchmark import PointBenchmark
from unitrack_env.envs.base import SequenceEnv


class PointEnv(SequenceEnv, task="point"):
    """Observation: the frame's measured ``point``; action: the point; reward: -error (px)."""

    def __init__(self, root=None, shuffle=False, render_mode=None):
        # No images: nothing to decode or prefetch.
        super().__init__(decode_frames=False, prefetch=False, shuffle=shuffle,
                         render_mode=render_mode)
        self.scoring = PointBenchmark.from_kwargs(root=root)
        self.sequence_names = self.scoring.sequence_names
        self.observation_space = spaces.Dict(
            {"point": spaces.Box(-1e4, 1e4, (2,), np.float32)})
        self.action_space = spaces.Box(-1e4, 1e4, (2,), np.float32)
        self._results = []

    # ----------------------------------------------------------- the episode hooks
    def _load(self, name):
        self._sequence = self.scoring.dataset.sequence(name)
        self._results = []
        return {"seq_length": self._length(), "has_ground_truth": True}

    def _length(self):
        return len(self._sequence.truth)

    def _frame_path(self, t):
        return Path(f"{self._sequence.name}-{t}")  # never read: decode_frames=False

    def _observe(self, t):
        return {"point": self._sequence.measured[t].astype(np.float32)}

    def _record(self, action, t):
        point = np.asarray(action, dtype=np.float64).reshape(2)
        self._results.append(point)
        return -float(np.linalg.norm(point - self._sequence.truth[t])), {}

    def episode_metrics(self):
        return self.scoring.score_sequence(self._sequence.name, self.episode_results())

    def _draw(self):
        return np.zeros((8, 8, 3), dtype=np.uint8)

    # ----------------------------------------------------------- results: the benchmark's
    def episode_results(self):
        return np.asarray(self._results, dtype=np.float64).reshape(-1, 2)

    def episode_digest(self):
        return self.scoring.digest(self.episode_results())

    def write_episode(self, folder):
        self.scoring.write(folder, self._sequence.name, self.episode_results())

    def sequence_length(self, name):
        return self.scoring.sequence_length(name)

    def has_ground_truth(self, name):
        return self.scoring.has_ground_truth(name)

    def score_folder(self, folder, sequences):
        return self.scoring.score_folder(folder, sequences)
'''

AGENT = '''
"""The trivial point tracker: it answers the measurement."""

from unitrack_env.agents import Agent


class EchoAgent(Agent):
    tasks = ("point",)

    def reset(self, observation, info):
        pass

    def act(self, observation):
        return observation["point"]
'''


def _write_project(folder: Path) -> Path:
    package = folder / "point_task"
    package.mkdir(parents=True)
    for name, text in {"__init__": INIT, "benchmark": BENCHMARK, "env": ENV,
                       "agent": AGENT}.items():
        (package / f"{name}.py").write_text(textwrap.dedent(text).lstrip())
    data = folder / "data"
    data.mkdir()
    sequences = {}
    for k, (dx, dy) in enumerate([(2.0, 1.0), (-1.5, 3.0)], start=1):
        truth = [[50 + dx * t, 40 + dy * t] for t in range(12)]
        noise = [[(-1) ** t * 2.0 * k, (t % 3) * 3.0] for t in range(12)]
        measured = [[x + nx, y + ny] for (x, y), (nx, ny) in zip(truth, noise, strict=True)]
        sequences[f"dot-{k}"] = {"truth": truth, "measured": measured}
    (data / "points.json").write_text(json.dumps(sequences))
    return data


@pytest.fixture
def project(tmp_path, monkeypatch):
    """The user's project on ``sys.path``, its row registered; all undone afterwards."""
    data = _write_project(tmp_path / "project")
    monkeypatch.syspath_prepend(str(tmp_path / "project"))
    monkeypatch.setattr(registration, "_ADDED", [])
    import point_task  # noqa: F401 - registers the row

    yield data
    gym.registry.pop(ENV_ID, None)
    for name in [m for m in sys.modules if m == "point_task" or m.startswith("point_task.")]:
        del sys.modules[name]


def test_a_new_task_runs_through_evaluate_and_score(project, tmp_path, capsys):
    out = tmp_path / "run"
    common = ["--env", ENV_ID, "--root", str(project)]
    assert main(["evaluate", *common, "--agent", "point_task.agent:EchoAgent",
                 "--out", str(out), "--format", "json"]) == 0
    evaluated = json.loads(capsys.readouterr().out)
    assert sorted(p.name for p in (out / "data").iterdir()) == ["dot-1.txt", "dot-2.txt"]
    assert set(evaluated["combined"]) == {"MeanError", "Success@5px"}
    assert 0.0 < evaluated["combined"]["MeanError"] < 10.0

    assert main(["score", *common, "--results", str(out / "data"), "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out) == evaluated

    assert main(["score", *common, "--results", str(out / "data")]) == 0
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
