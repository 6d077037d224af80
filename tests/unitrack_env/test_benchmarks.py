"""Every registered id's benchmark writes, digests and scores exactly as its environment does.

For each id on the embedded synthetic data, a baseline agent plays two sequences; the
environment's result files and the benchmark's must be byte-identical, and scoring the
folder through the benchmark must give the environment's numbers to the digit.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import unitrack_env
from unitrack_env.agents import make_agent
from unitrack_env.benchmarks import Benchmark, benchmark_class, benchmark_for, task_columns
from unitrack_env.registration import variant

ALL_IDS = unitrack_env.env_ids()
#: A cheap agent per task (none of them looks at pixels).
AGENTS = {"mot": "iou", "mots": "iou", "vis": "iou", "posetrack": "iou", "sot": "repeat-box",
          "vos": "repeat-mask", "pose-prop": "repeat-pose", "points": "static-points"}


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _results(env) -> object:
    """What the environment recorded in the episode (JHMDB names it predictions)."""
    if hasattr(env, "episode_results"):
        return env.episode_results()
    return env.episode_results()


def _same(a: dict, b: dict) -> None:
    """Equal to the digit, NaN equal to NaN."""
    assert json.dumps(a, sort_keys=True, default=str) == json.dumps(b, sort_keys=True,
                                                                    default=str)
    for key, value in a.items():
        if isinstance(value, float) and math.isnan(value):
            assert math.isnan(b[key])


def _play(env, agent, name: str) -> dict:
    observation, info = env.reset(options={"sequence": name})
    agent.reset(observation, info)
    done = False
    while not done:
        observation, _, terminated, truncated, info = env.step(agent.act(observation))
        done = terminated or truncated
    return info


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_benchmark_writes_and_scores_like_the_env(env_id, tmp_path):
    env = gym.make(env_id, decode_frames=False).unwrapped
    bench = benchmark_for(env_id)
    assert isinstance(bench, benchmark_class(env_id))
    assert bench.task == variant(env_id).task
    names = list(env.sequence_names)[:2]
    assert list(bench.sequence_names) == list(env.sequence_names)
    agent = make_agent(AGENTS[bench.task])
    try:
        for name in names:
            assert bench.sequence_length(name) == env.sequence_length(name)
            assert bench.has_ground_truth(name) == env.has_ground_truth(name)
            info = _play(env, agent, name)
            env.write_episode(tmp_path / "env")
            results = _results(env)
            if hasattr(bench, "score_sequence") and "metrics" in info:
                _same(bench.score_sequence(name, results), info["metrics"])
            bench.write(tmp_path / "bench", name, results)
            assert bench.digest(results) == env.episode_digest()
            assert bench.read(tmp_path / "bench", name) is not None
        assert _files(tmp_path / "bench") == _files(tmp_path / "env")
        scored = bench.scorable(names)
        ours = bench.score_folder(tmp_path / "bench", scored)
        theirs = env.score_folder(tmp_path / "env", scored)
    finally:
        agent.close()
        env.close()
    assert ours.benchmark == theirs.benchmark == bench.name
    assert ours.per_sequence.keys() == theirs.per_sequence.keys()
    for name in ours.per_sequence:
        _same(ours.per_sequence[name], theirs.per_sequence[name])
    _same(ours.combined, theirs.combined)
    assert ours.to_json() == theirs.to_json()
    assert set(bench.columns) & set(ours.combined), "no result column is a scored metric"


def test_benchmark_for_applies_the_row_defaults_then_the_arguments():
    assert benchmark_for("UniTrack/MOT16-v0").name == "MOT16"
    assert benchmark_for("UniTrack/MOTChallenge-v0", benchmark="MOT20").name == "MOT20"


def test_task_columns_come_from_the_benchmarks():
    assert task_columns("mot")[:3] == ("HOTA", "IDF1", "MOTA")
    assert task_columns("vos")[0] == "J&F-Mean"
    assert task_columns("no-such-task") == ()


def test_benchmark_is_abstract():
    with pytest.raises(TypeError):
        Benchmark(None)  # type: ignore[abstract]

    class Partial(Benchmark):
        task = "x"

    with pytest.raises(TypeError, match="abstract"):
        Partial(None)  # type: ignore[abstract]


def test_unknown_id_is_a_clear_error():
    with pytest.raises(KeyError, match="not a unitrack id"):
        benchmark_for("UniTrack/Nope-v0")


def test_benchmark_write_is_atomic(tmp_path, monkeypatch):
    bench = benchmark_for("UniTrack/MOT17-v0")
    rows = np.array([[1, 1, 10.0, 20.0, 30.0, 40.0, 1, -1, -1, -1]])
    bench.write(tmp_path, "SYN-01", rows)
    assert (tmp_path / "SYN-01.txt").read_text() == "1,1,10.000,20.000,30.000,40.000,1,-1,-1,-1\n"
    assert [p.name for p in tmp_path.iterdir()] == ["SYN-01.txt"]
    np.testing.assert_array_equal(bench.read(tmp_path, "SYN-01")[:, :6], rows[:, :6])


@pytest.mark.parametrize(("env_id", "kwargs", "message"), [
    ("UniTrack/MOTChallenge-v0", {"benchmark": "MOT99"}, "unknown benchmark 'MOT99'"),
    ("UniTrack/MOTS-v0", {"benchmark": "MOTS99"}, "unknown benchmark 'MOTS99'"),
    ("UniTrack/MOTS-v0", {"object_class": "car"}, "not a MOTS20 class"),
    ("UniTrack/JHMDB-v0", {"normaliser": "torso"}, "normaliser must be one of"),
])
def test_benchmark_refuses_what_the_env_refuses(env_id, kwargs, message):
    with pytest.raises(ValueError, match=message):
        benchmark_for(env_id, **kwargs)
    with pytest.raises(ValueError, match=message):
        gym.make(env_id, **kwargs)
