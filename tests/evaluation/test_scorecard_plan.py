"""The scorecard's plan: cells from the benchmarks, known before any data are written or torch
is imported, and the first ETA within a second."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import pytest

from unitrack_env.benchmarks import benchmark_for
from unitrack_env.datasets.synthetic.cache import SpecsOnly, specs_only
from unitrack_env.evaluation.scorecard.plan import TASKS, ModelSpec, data_source, plan

REPO = Path(__file__).resolve().parents[2]
MODELS = [ModelSpec.parse("imagenet-lite0"), ModelSpec.parse("random")]


def _key(cell):
    return cell.label


def test_synthetic_cells_are_known_before_the_data_are_written(tmp_path, monkeypatch):
    session_cache = os.environ["UNITRACK_CACHE"]
    empty = tmp_path / "empty-cache"
    monkeypatch.setenv("UNITRACK_CACHE", str(empty))
    early, _, pending = plan(MODELS, list(TASKS), None, generate=False)
    assert pending == list(TASKS)
    assert not empty.exists()  # nothing written
    with specs_only(), pytest.raises(SpecsOnly) as asked:
        benchmark_for("UniTrack/DAVIS-v0")
    assert (asked.value.benchmark, asked.value.kind.name, asked.value.generated) == \
        ("DAVIS-2017", "davis", False)
    monkeypatch.setenv("UNITRACK_CACHE", session_cache)  # generated once per test session
    cells, _, pending = plan(MODELS, list(TASKS), None)
    assert pending == []
    assert sorted(early, key=_key) == sorted(cells, key=_key)
    assert plan(MODELS, list(TASKS), None, generate=False)[2] == []  # now generated


def test_the_plan_counts_what_the_environments_play(shared_data):
    cells, sources, _ = plan(MODELS[:1], list(TASKS), shared_data)
    for name, source in sources.items():
        env = gym.make(source.env_id, **({"root": source.root} if source.root else {}))
        base = env.unwrapped
        expected = {s: base.sequence_length(s) for s in base.sequence_names
                    if base.has_ground_truth(s)}
        env.close()
        for head in (*TASKS[name].heads, TASKS[name].baseline):
            assert {c.sequence: c.frames for c in cells
                    if c.task == name and c.head == head.label} == expected, (name, head)
    assert data_source(shared_data, TASKS["mot"]).kind == "fixture"


def test_the_first_eta_comes_before_torch_is_imported_then_the_exact_one(tmp_path):
    """The real command line, in a fresh interpreter: the bar's first two estimates."""
    script = textwrap.dedent(f"""
        import os, sys
        from unitrack_env.evaluation.cli import scorecard as cli_scorecard
        from unitrack_env.evaluation.cli import main
        seen = []
        def estimate(self, seconds):
            seen.append(("torch" in sys.modules, seconds))
            if len(seen) == 2:
                print(seen, flush=True)
                os._exit(0)
        cli_scorecard._Update.estimate = estimate
        main(["scorecard", "--model", "imagenet-lite0", "--tasks", "pose-prop", "--runtime",
              "torch", "--out", {str(tmp_path / "card")!r}])
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=300)
    assert done.returncode == 0, done.stderr
    (torch_first, first), (torch_second, second) = eval(done.stdout)  # noqa: S307
    assert not torch_first and torch_second
    assert first > second > 0  # the same cells and GFLOP; the first also counts the setup
