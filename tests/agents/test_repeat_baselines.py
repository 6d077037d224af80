"""The repeat-first-target baselines: registry, behaviour, and end-to-end runs with the runner."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.agents import available_agents, make_agent
from unitrack_env.agents.base import agent_class
from unitrack_env.evaluation.run.runner import run


def test_registered_with_their_tasks():
    assert {"repeat-box", "repeat-mask"} <= set(available_agents())
    assert agent_class("repeat-box").tasks == ("sot",)
    assert agent_class("repeat-mask").tasks == ("vos",)


def test_repeat_box_returns_the_initial_box_every_frame():
    agent = make_agent("repeat-box")
    with pytest.raises(RuntimeError, match="reset"):
        agent.act({})
    init = np.array([10, 20, 30, 40], np.float32)
    agent.reset({"frame": np.zeros((4, 4, 3), np.uint8), "init_box": init}, {})
    first = agent.act({"init_box": np.zeros(4, np.float32)})
    first[0] = 99  # the agent hands out copies
    second = agent.act({})
    assert second.dtype == np.float32 and second.tolist() == [10, 20, 30, 40]


def test_repeat_mask_returns_the_first_labels_without_void():
    agent = make_agent("repeat-mask")
    init = np.array([[0, 1, 255], [2, 2, 0]], np.uint8)
    agent.reset({"init_labels": init, "num_objects": 2}, {})
    answer = agent.act({})
    assert answer.dtype == np.uint8
    np.testing.assert_array_equal(answer, [[0, 1, 0], [2, 2, 0]])
    assert init[0, 2] == 255  # the observation is not modified


def _metrics(out: Path) -> dict:
    return json.loads((out / "metrics.json").read_text())


def test_runner_end_to_end_on_the_synthetic_defaults(tmp_path):
    sot = run("UniTrack/OTB-v0", "repeat-box", out=tmp_path / "otb", progress=False)
    assert sorted(sot.records) == ["SynCrossing", "SynLateStart", "SynWalker"]
    assert sorted(p.name for p in (tmp_path / "otb" / "data").iterdir()) == [
        "SynCrossing.txt", "SynLateStart.txt", "SynWalker.txt"]
    assert 0.1 < sot.combined["AUC"] < 0.4  # a still box: a floor, far from 20/21
    assert _metrics(tmp_path / "otb")["combined"] == sot.combined
    for record in sot.records.values():  # return / frames = mean overlap
        per_sequence = sot.scores.per_sequence[record.sequence]
        assert record.episode_return / record.frames == pytest.approx(
            per_sequence["AverageOverlap"])

    vos = run("UniTrack/DAVIS-v0", "repeat-mask", out=tmp_path / "davis", progress=False)
    assert sorted(vos.records) == ["syn-crossing", "syn-occluded"]
    assert (tmp_path / "davis" / "data" / "syn-crossing" / "00029.png").is_file()
    assert 0.1 < vos.combined["J-Mean"] < 0.5
    assert vos.combined["J&F-Mean"] == pytest.approx(
        (vos.combined["J-Mean"] + vos.combined["F-Mean"]) / 2)
    for record in vos.records.values():  # return / scored frames = J-Mean
        per_sequence = vos.scores.per_sequence[record.sequence]
        assert record.episode_return / (record.frames - 2) == pytest.approx(
            per_sequence["J-Mean"])


def test_runner_on_a_split_without_ground_truth(tmp_path):
    report = run("UniTrack/DAVIS-v0", "repeat-mask", out=tmp_path, progress=False,
                 env_kwargs={"split": "test-dev"})
    assert report.scores is None and report.combined == {}
    assert len(list((tmp_path / "data" / "syn-test").iterdir())) == 12


def test_runner_on_the_real_fixtures(shared_data, tmp_path):
    sot = run("UniTrack/OTB-v0", "repeat-box", out=tmp_path / "otb", progress=False,
              env_kwargs={"root": str(shared_data / "OTB")}, sequences=["Crossing"])
    assert sot.combined["AUC"] < 0.1
    vos = run("UniTrack/DAVIS-v0", "repeat-mask", out=tmp_path / "davis", progress=False,
              env_kwargs={"root": str(shared_data / "DAVIS")}, sequences=["blackswan"])
    assert vos.combined["J-Mean"] == pytest.approx(0.545, abs=1e-3)
