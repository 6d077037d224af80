"""``run(..., repeats=K)`` / ``unitrack evaluate --repeats K``: every repetition written, spread.

GOT-10k writes the server's ``<seq>/<seq>_00k.txt`` and ``<seq>_time.txt`` (the got10k
toolkit's ``ExperimentGOT10k._record`` layout); other benchmarks write repetition ``k`` into
``data/repeat-00k/``. A deterministic agent gives zero spread, a seeded random one does not.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from unitrack_env.agents.base import Agent
from unitrack_env.evaluation.run.repetitions import spread
from unitrack_env.evaluation.run.runner import run


class JitterBox(Agent):
    """The first box moved by seeded noise: its generator runs on across episodes."""

    tasks = ("sot",)

    def __init__(self, seed: int = 0, jitter: float = 4.0) -> None:
        self.rng, self.jitter = np.random.default_rng(seed), jitter

    def reset(self, observation: Any, info: dict[str, Any]) -> None:
        self.box = np.asarray(observation["init_box"], dtype=np.float64)

    def act(self, observation: Any) -> np.ndarray:
        moved = self.box + self.rng.normal(0, self.jitter, 4) * [1, 1, 0.5, 0.5]
        return np.maximum(moved, [0, 0, 1, 1])


def _metrics(out) -> dict[str, Any]:
    return json.loads((out / "metrics.json").read_text())


def test_spread_is_mean_min_max_over_finite_values():
    rows = [{"AUC": 0.5, "n": "x"}, {"AUC": 0.7, "n": "y"}, {"AUC": float("nan"), "n": "z"}]
    assert spread(rows) == {"AUC": {"mean": pytest.approx(0.6), "min": 0.5, "max": 0.7}}


def test_got10k_repeats_write_the_servers_files_and_a_deterministic_agent_has_no_spread(
        tmp_path):
    report = run("UniTrack/GOT10k-v0", "repeat-box", out=tmp_path / "r", repeats=3,
                 progress=False)
    data = tmp_path / "r" / "data"
    for name in report.records:
        runs = [np.loadtxt(data / name / f"{name}_{k:03d}.txt", delimiter=",")
                for k in (1, 2, 3)]
        assert all(np.array_equal(runs[0], other) for other in runs[1:])
        # got10k's report reads the time file as it writes it: one column per repetition.
        times = np.loadtxt(data / name / f"{name}_time.txt", delimiter=",")
        assert times.shape == (len(runs[0]), 3) and (times >= 0).all()
    stats = _metrics(tmp_path / "r")["repetitions"]
    assert stats["repeats"] == 3 and len(stats["combined"]) == 3
    for metric, values in stats["spread"]["combined"].items():
        assert values["min"] == values["max"] == pytest.approx(values["mean"]), metric
    assert report.repetitions["spread"]["combined"]["AO"]["mean"] == pytest.approx(
        report.combined["AO"])
    # the stored run (its run.json says repeats=3) is checked as such, and nothing is stale
    from unitrack_env.evaluation.run.resume import stale_sequences

    assert stale_sequences("UniTrack/GOT10k-v0", "repeat-box", tmp_path / "r") == {}


def test_a_seeded_random_agent_spreads_and_each_repetition_is_scored_alone(tmp_path):
    agent = f"{__name__}:JitterBox"
    report = run("UniTrack/OTB-v0", agent, out=tmp_path / "o", repeats=3, progress=False)
    data = tmp_path / "o" / "data"
    stats = _metrics(tmp_path / "o")["repetitions"]
    auc = stats["spread"]["combined"]["AUC"]
    assert auc["min"] < auc["max"]
    # repetition 1 is the run's official result; repetition k is data/repeat-00k/, scored alone
    assert stats["combined"][0]["AUC"] == pytest.approx(report.combined["AUC"])
    bench = report.scores
    for k in (2, 3):
        folder = data / f"repeat-{k:03d}"
        assert sorted(p.stem for p in folder.glob("*.txt")) == sorted(bench.per_sequence)
    # the same seed gives the same run: the spread is the agent's, not the harness's
    again = run("UniTrack/OTB-v0", agent, out=tmp_path / "o2", repeats=3, progress=False)
    assert again.repetitions["combined"] == report.repetitions["combined"]


def test_a_run_with_other_repeats_is_refused_and_one_repeat_keeps_the_old_run_json(tmp_path):
    from unitrack_env.evaluation.run.resume import RunMismatch

    run("UniTrack/OTB-v0", "repeat-box", out=tmp_path / "one", sequences=["SynWalker"],
        progress=False)
    assert "repeats" not in json.loads((tmp_path / "one" / "run.json").read_text())
    assert "repetitions" not in _metrics(tmp_path / "one")
    with pytest.raises(RunMismatch, match="--repeats: 1 -> 2"):
        run("UniTrack/OTB-v0", "repeat-box", out=tmp_path / "one", sequences=["SynWalker"],
            repeats=2, progress=False)
    with pytest.raises(ValueError, match="repeats must be a whole number"):
        run("UniTrack/OTB-v0", "repeat-box", out=tmp_path / "zero", repeats=0, progress=False)


def test_got10k_toolkit_report_reads_the_run_folder_and_agrees(tmp_path, got10k_experiments):
    """got10k's own ExperimentGOT10k.report on the written folder: same AO and SR, a speed."""
    import shutil

    from unitrack_env.benchmarks import benchmark_for

    report = run("UniTrack/GOT10k-v0", f"{__name__}:JitterBox", out=tmp_path / "g",
                 repeats=3, progress=False)
    root = benchmark_for("UniTrack/GOT10k-v0").dataset.split_dir.parent
    results = tmp_path / "results" / "GOT-10k" / "mine"
    shutil.copytree(tmp_path / "g" / "data", results)
    experiment = got10k_experiments.ExperimentGOT10k(
        str(root), subset="val", result_dir=str(tmp_path / "results"),
        report_dir=str(tmp_path / "reports"))
    import matplotlib.pyplot as plt

    before = set(plt.get_fignums())
    overall = experiment.report(["mine"])["mine"]["overall"]
    for number in set(plt.get_fignums()) - before:  # got10k's report leaves its plot open
        plt.close(number)
    assert overall["ao"] == pytest.approx(report.combined["AO"], abs=1e-6)
    assert overall["sr"] == pytest.approx(report.combined["SR0.5"], abs=1e-6)
    assert np.isfinite(overall["speed_fps"]) and overall["speed_fps"] > 0
    spread_ao = report.repetitions["spread"]["combined"]["AO"]
    assert spread_ao["min"] < spread_ao["max"]


def test_cli_repeats_prints_the_spread_table(tmp_path, capsys):
    from unitrack_env.evaluation.cli import main

    out = str(tmp_path / "c")
    assert main(["evaluate", "--env", "UniTrack/OTB-v0", "--agent", f"{__name__}:JitterBox",
                 "--sequences", "SynWalker", "--repeats", "2", "--out", out, "--quiet",
                 "--in-process"]) == 0
    printed = capsys.readouterr().out
    assert "spread over 2 repetitions: mean [min, max]" in printed
    stats = _metrics(tmp_path / "c")["repetitions"]["spread"]["combined"]["AUC"]
    assert f"{100 * stats['mean']:.1f} [{100 * stats['min']:.1f}, {100 * stats['max']:.1f}]" \
        in printed
