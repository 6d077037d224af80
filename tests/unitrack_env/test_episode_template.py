"""The episode template: SequenceEnv owns reset/step; a task env only supplies its hooks."""

from __future__ import annotations

import importlib

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env

import unitrack_env
from unitrack_env import render
from unitrack_env.benchmarks.base import Benchmark, rounded_digest
from unitrack_env.envs.base import SequenceEnv
from unitrack_env.metrics.report import ScoreReport


class _Dots:
    """Two sequences of points (the 'data set')."""

    sequence_names = ["a", "b"]
    truth = {"a": np.arange(10.0).reshape(5, 2), "b": np.arange(6.0).reshape(3, 2)}


class _DotBenchmark(Benchmark):
    task = "dot"
    columns = ("Error",)

    @classmethod
    def build(cls):
        return cls(_Dots())

    @property
    def name(self):
        return "Dots"

    def sequence_length(self, name):
        return len(self.dataset.truth[name])

    def has_ground_truth(self, name):
        return name == "a"

    def write(self, folder, sequence, results):
        np.save(f"{folder}/{sequence}.npy", results)

    def read(self, folder, sequence):
        return np.load(f"{folder}/{sequence}.npy")

    def digest(self, results):
        return rounded_digest(results)

    def score_sequence(self, sequence, results):
        return {"Error": float(np.abs(results - self.dataset.truth[sequence]).mean())}

    def score_files(self, folder, sequences):
        per = {name: self.score_sequence(name, self.read(folder, name)) for name in sequences}
        return ScoreReport("Dots", per, {}, per)


class DotEnv(SequenceEnv):
    """A toy task written against the template: only hooks, no reset/step."""

    def __init__(self, **options):
        super().__init__(**options)
        self.scoring = _DotBenchmark.build()
        self.sequence_names = self.scoring.sequence_names
        self.observation_space = spaces.Dict({"point": spaces.Box(-1e4, 1e4, (2,), np.float32)})
        self.action_space = spaces.Box(-1e4, 1e4, (2,), np.float32)
        self._results = []

    def _load(self, name):
        self._sequence = type("Seq", (), {"name": name, "points": self.scoring.dataset.truth[name]})
        self._results = []
        return {"seq_length": len(self._sequence.points),
                "has_ground_truth": self.scoring.has_ground_truth(name)}

    def _length(self):
        return len(self._sequence.points)

    def _frame_path(self, t):
        return f"/nowhere/{t}.jpg"

    def _frame_size(self):
        return (1, 1)

    def _observe(self, t):
        return {"point": self._sequence.points[t].astype(np.float32)}

    def _record(self, action, t):
        self._results.append(np.asarray(action, np.float64))
        self._answer = action
        return -float(np.abs(self._results[-1] - self._sequence.points[t]).sum()), {"t": t}

    def episode_results(self):
        return np.asarray(self._results).reshape(-1, 2)

    def _draw(self):
        return np.zeros((4, 4, 3), np.uint8)


def _toy():
    return DotEnv(decode_frames=False)


def test_step_before_reset_or_after_close_says_which():
    env = _toy()
    with pytest.raises(RuntimeError, match=r"step\(\) called before any reset\(\)"):
        env.step(np.zeros(2))
    observation, _ = env.reset(options={"sequence": "a"})
    env.close()
    with pytest.raises(RuntimeError, match=r"step\(\) called after close\(\); call reset"):
        env.step(observation["point"])
    observation, _ = env.reset(options={"sequence": "a"})  # a closed env starts again
    assert env.step(observation["point"])[1] == 0.0


def test_template_plays_an_episode_from_hooks_only(tmp_path):
    env = _toy()
    observation, info = env.reset(options={"sequence": "a"})
    assert info == {"sequence": "a", "frame_index": 0, "seq_length": 5,
                    "has_ground_truth": True, "task": "dot", "capacities": {}}
    steps, terminated = 0, False
    while not terminated:
        last = observation
        observation, reward, terminated, truncated, info = env.step(observation["point"])
        steps += 1
        assert reward == 0.0 and not truncated and info["t"] == steps - 1
    assert steps == 5 and info["frame_index"] == 4 and info["metrics"] == {"Error": 0.0}
    np.testing.assert_array_equal(observation["point"], last["point"])
    assert observation["point"] is not last["point"]  # the terminal observation is fresh
    with pytest.raises(RuntimeError, match="on a finished episode; call reset"):
        env.step(observation["point"])
    env.write_episode(tmp_path)
    assert env.score_folder(tmp_path, ["a"]).per_sequence == {"a": {"Error": 0.0}}
    assert env.episode_digest() == rounded_digest(env.episode_results())


def test_no_metrics_without_ground_truth():
    env = _toy()
    env.reset(options={"sequence": "b"})
    for _ in range(3):
        *_, terminated, _, info = env.step(np.zeros(2, np.float32))
    assert terminated and "metrics" not in info
    with pytest.raises(ValueError, match="no ground truth"):
        env.episode_metrics()


def test_a_task_env_must_implement_the_hooks():
    class Incomplete(SequenceEnv):
        pass

    with pytest.raises(TypeError, match="_load"):
        Incomplete()


def test_step_before_reset_is_refused():
    with pytest.raises(RuntimeError, match="call reset"):
        _toy().step(np.zeros(2, np.float32))


@pytest.mark.parametrize("env_id", unitrack_env.env_ids())
def test_terminal_observation_repeats_the_last_one_with_fresh_arrays(env_id):
    env = gym.make(env_id, decode_frames=False).unwrapped
    name = env.sequence_names[0]
    observation, _ = env.reset(options={"sequence": name})
    env.action_space.seed(0)
    action = env.action_space.sample()
    if isinstance(action, dict):
        action = {k: min(v, 2) if k.startswith("num_") else v for k, v in action.items()}
    terminated = False
    while not terminated:
        last = observation
        observation, _, terminated, _, _ = env.step(action)
    for key, value in last.items():
        np.testing.assert_array_equal(np.asarray(observation[key]), np.asarray(value))
        if isinstance(value, np.ndarray):
            assert observation[key] is not value


def test_toy_env_passes_check_env():
    check_env(_toy(), skip_render_check=True)


def test_envs_do_not_import_each_other():
    from pathlib import Path

    folder = Path(unitrack_env.__file__).parent / "envs"
    for path in folder.glob("*.py"):
        text = path.read_text()
        # base modules shared by several envs: the template, and the envs with classes
        shared = ("base", "__init__", "classed_mot", "track_classes")
        others = [p.stem for p in folder.glob("*.py") if p.stem not in shared]
        for other in others:
            assert f"unitrack_env.envs.{other} import" not in text, f"{path.name} -> {other}"
    assert render.draw_masks is importlib.import_module("unitrack_env.envs.mots").draw_masks
