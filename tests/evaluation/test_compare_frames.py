"""`unitrack compare` of SOT, VOS and JHMDB runs: per-frame metrics recomputed from the events
equal the official scores, and the paired block jackknife is the MOT one."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.evaluation.analysis.compare import COMBINED, jackknife_interval
from unitrack_env.evaluation.analysis.events import run_benchmark
from unitrack_env.evaluation.analysis.intervals import compare_runs, frame_replicates, run_intervals
from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.run.runner import run


def metrics(run_dir: Path) -> dict:
    return json.loads((run_dir / "metrics.json").read_text())


@pytest.fixture(scope="module")
def sot_runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """``repeat-box``, and a copy whose boxes are shifted 6 px (events recomputed)."""
    root = tmp_path_factory.mktemp("compare-frames")
    a = root / "a"
    run("UniTrack/OTB-v0", "repeat-box", out=a, progress=False)
    b = root / "b"
    shutil.copytree(a, b)
    shutil.rmtree(b / "events")
    for path in (b / "data").glob("*.txt"):
        boxes = np.loadtxt(path, delimiter=",", ndmin=2)
        boxes[:, :2] += 6
        np.savetxt(path, boxes, fmt="%.0f", delimiter=",")
    _restamp_results(b)  # as if a run had written these files (compare checks the digests)
    return a, b


def _restamp_results(run_dir: Path) -> None:
    from unitrack_env.evaluation.run.identity import result_digest

    names = run_benchmark(run_dir).sequence_names
    for record in (run_dir / "sequences").glob("*.json"):
        data = json.loads(record.read_text())
        data["results"] = result_digest(run_dir / "data", data["sequence"], names)
        record.write_text(json.dumps(data))


def test_sot_compare_recomputes_the_official_scores(sot_runs) -> None:
    a, b = sot_runs
    comp = compare_runs(a, b)
    official_b = run_benchmark(b).score_files(b / "data", list(metrics(b)["per_sequence"]))
    for name, row in comp.rows.items():
        ref_a = metrics(a)["combined"] if name == COMBINED else metrics(a)["per_sequence"][name]
        ref_b = official_b.combined if name == COMBINED else official_b.per_sequence[name]
        for metric, d in row.items():
            assert (d.a, d.b) == pytest.approx((ref_a[metric], ref_b[metric]), abs=1e-3)
            assert d.low <= d.diff <= d.high and d.diff == pytest.approx(d.a - d.b)
    assert comp.rows[COMBINED]["AUC"].diff > 0  # the shifted boxes overlap less
    assert not comp.rows[COMBINED]["AUC"].reliable  # 106 synthetic frames: said plainly
    low, high = run_intervals(a)["AUC"]
    assert low < metrics(a)["combined"]["AUC"] < high


@pytest.mark.parametrize(("env", "agent"), [("UniTrack/DAVIS-v0", "repeat-mask"),
                                            ("UniTrack/JHMDB-v0", "repeat-pose")])
def test_vos_and_jhmdb_compare_recompute_the_official_scores(env, agent, tmp_path) -> None:
    run(env, agent, out=tmp_path / "a", progress=False)
    comp = compare_runs(tmp_path / "a", tmp_path / "a", level="sequences")
    found = metrics(tmp_path / "a")
    for name, row in comp.rows.items():
        ref = found["combined"] if name == COMBINED else found["per_sequence"][name]
        for metric, d in row.items():
            assert d.a == pytest.approx(ref[metric], abs=1e-4), (name, metric)
            assert d.diff == d.low == d.high == 0.0


def test_frame_replicates_combine_like_the_official_scores() -> None:
    values = {"s1": np.array([1.0, 1.0, 1.0, 1.0]), "s2": np.array([0.0, 0.0, np.nan, 0.0,
                                                                    0.0, 0.0])}
    blocks = {"s1": 2, "s2": 2}
    pooled = frame_replicates(values, blocks)
    assert pooled[COMBINED][0] == pytest.approx(4 / 9)
    assert pooled["s2"][0] == 0.0 and len(pooled[COMBINED][1]) == 2 + 3
    equal = frame_replicates(values, blocks, level="sequences", weights={"s1": 1, "s2": 1})
    assert equal[COMBINED][0] == 0.5 and list(equal[COMBINED][1]) == [0.0, 1.0]
    point, reps = equal[COMBINED]
    low, high = jackknife_interval(point, reps)
    assert low < 0 < 1 < high  # two sequences that disagree: a wide interval


def test_compare_command_on_sot_runs(sot_runs, capsys, tmp_path) -> None:
    a, b = sot_runs
    assert main(["compare", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    assert "COMBINED           AUC" in out and "Precision@20px" in out and "too little" in out
    assert main(["compare", str(a), str(b), "--interval", "percentile"]) == 2
    assert "compared with the block jackknife" in capsys.readouterr().err
    other = tmp_path / "other"
    shutil.copytree(a, other)
    spec = json.loads((other / "run.json").read_text())
    (other / "run.json").write_text(json.dumps(spec | {"env_id": "UniTrack/DAVIS-v0",
                                                       "env_kwargs": {}}))
    assert main(["compare", str(a), str(other)]) == 2
    assert "a sot run" in capsys.readouterr().err


def test_report_compares_two_sot_runs(sot_runs, tmp_path) -> None:
    from unitrack_env.evaluation.report.build import build_report

    page = build_report(list(sot_runs), tmp_path).read_text()
    section = page.split('<h2 id="compare">', 1)[1].split("<h2", 1)[0]
    assert "jackknife" in section and "AUC" in section and "Precision@20px" in section


def test_frame_blocks_are_long_and_the_combined_row_needs_five_of_them() -> None:
    from unitrack_env.evaluation.analysis.compare import frame_block_length, unreliable_rows

    assert [frame_block_length(n) for n in (30, 100, 120, 199, 400)] == [15, 50, 50, 50, 80]
    otb = {"Crossing": 120, "Human3": 199}
    blocks = {n: frame_block_length(f) for n, f in otb.items()}
    assert unreliable_rows(otb, blocks, pooled=True) == ["Crossing", "Human3"]
    short = {"a": 40, "b": 40, "c": 40}  # six blocks, but of 20 frames
    assert COMBINED in unreliable_rows(short, {n: frame_block_length(40) for n in short},
                                       pooled=True)
