"""What compare and report check before reading a run: its result files and data as scored."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from unitrack_env.datasets.synthetic import ensure_synthetic
from unitrack_env.evaluation.analysis.events import run_benchmark
from unitrack_env.evaluation.run.integrity import (
    DifferentData,
    StaleRun,
    check_current,
    check_pair,
    data_fingerprint,
)
from unitrack_env.evaluation.run.runner import run

ENV = "UniTrack/MOT17-v0"


def _copy_data(dst: Path) -> Path:
    src = ensure_synthetic("MOT17", "motchallenge")
    for folder, _, files in os.walk(src):
        rel = Path(folder).relative_to(src)
        (dst / rel).mkdir(parents=True, exist_ok=True)
        for name in files:
            shutil.copyfile(Path(folder) / name, dst / rel / name)
    return dst


@pytest.fixture(scope="module")
def scored(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    base = tmp_path_factory.mktemp("integrity")
    root = _copy_data(base / "data")
    out = base / "run"
    run(ENV, "iou", out=out, progress=False, env_kwargs={"root": str(root), "decode_frames": False})
    return out, root


def test_records_keep_the_data_fingerprint_and_a_fresh_run_passes(scored) -> None:
    out, root = scored
    bench = run_benchmark(out)
    names = list(json.loads((out / "metrics.json").read_text())["per_sequence"])
    now = check_current(out, bench, names)
    for name in names:
        record = json.loads((out / "sequences" / f"{name}.json").read_text())
        assert record["data"] == now[name] == data_fingerprint(bench.dataset, name, out) != ""
    check_pair(out, bench, out, bench, names)  # a run against itself


def test_an_older_record_without_a_fingerprint_is_still_paired_by_todays_data(
        scored, tmp_path: Path) -> None:
    out, root = scored
    other_root = _copy_data(tmp_path / "data")
    gt = other_root / "train" / "SYN-02" / "gt" / "gt.txt"
    gt.write_text("".join(gt.read_text().splitlines(keepends=True)[1:]))
    other = tmp_path / "run"
    shutil.copytree(out, other)
    spec = json.loads((other / "run.json").read_text())
    spec["env_kwargs"]["root"] = str(other_root)
    (other / "run.json").write_text(json.dumps(spec))
    for record in (other / "sequences").glob("*.json"):  # records written before `data`
        data = json.loads(record.read_text())
        del data["data"]
        record.write_text(json.dumps(data))
    bench, other_bench = run_benchmark(out), run_benchmark(other)
    names = ["SYN-01", "SYN-02"]
    assert check_current(other, other_bench, names)  # nothing recorded to hold it against
    with pytest.raises(DifferentData, match=r"different data for SYN-02 \("):
        check_pair(out, bench, other, other_bench, names)
    check_pair(out, bench, other, other_bench, ["SYN-01"])
    (other / "data" / "SYN-01.txt").write_text("")
    with pytest.raises(StaleRun, match="result files of SYN-01 were changed"):
        check_pair(out, bench, other, other_bench, ["SYN-01"])


def test_runs_written_inside_the_data_folder_are_not_data(tmp_path: Path) -> None:
    root = _copy_data(tmp_path / "data")
    first, second = root / "runs" / "first", root / "runs" / "second"
    for out in (first, second):  # the second run's files name SYN-01 too
        run(ENV, "iou", out=out, progress=False, sequences=["SYN-01"],
            env_kwargs={"root": str(root), "decode_frames": False})
    check_pair(first, run_benchmark(first), second, run_benchmark(second), ["SYN-01"])
