"""`unitrack compare` of LaSOT, UAV123 and GOT-10k runs: the per-frame values the intervals rest
on average to the official scores, absent frames, invalid ground truth and pooling included."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.evaluation.analysis.events import run_benchmark
from unitrack_env.evaluation.analysis.intervals import compare_runs
from unitrack_env.evaluation.run.runner import run

sys.path.insert(0, str(Path(__file__).parent))
from test_compare_frames import _restamp_results  # noqa: E402  (tests/ is not a package)


def _shifted_copy(a: Path, b: Path) -> None:
    """A copy of run ``a`` whose boxes are moved 6 px (events recomputed, digests restamped)."""
    shutil.copytree(a, b)
    shutil.rmtree(b / "events")
    for path in (b / "data").rglob("*.txt"):
        boxes = np.loadtxt(path, delimiter=",", ndmin=2)
        boxes[:, :2] += 6
        np.savetxt(path, boxes, fmt="%.0f", delimiter=",")
    _restamp_results(b)


@pytest.mark.parametrize(("env_id", "metrics"), [
    ("UniTrack/LaSOT-v0", {"AUC", "Precision@20px"}),
    ("UniTrack/UAV123-v0", {"AUC", "Precision@20px"}),
    ("UniTrack/GOT10k-v0", {"AO", "SR0.5", "SR0.75"})])
def test_compare_of_new_sot_envs_recomputes_the_official_scores(env_id, metrics, tmp_path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    run(env_id, "repeat-box", out=a, progress=False)
    _shifted_copy(a, b)
    bench = run_benchmark(b)
    names = list(json.loads((a / "metrics.json").read_text())["per_sequence"])
    official = [bench.score_files(run_dir / "data", names) for run_dir in (a, b)]
    comp = compare_runs(a, b, resamples=20)
    assert set(comp.rows) == {*names, "COMBINED"}
    for name, row in comp.rows.items():
        assert set(row) == metrics
        for metric, d in row.items():
            ref = [o.combined if name == "COMBINED" else o.per_sequence[name]
                   for o in official]
            assert (d.a, d.b) == pytest.approx((ref[0][metric], ref[1][metric]), abs=1e-9)
            assert d.low <= d.diff <= d.high
