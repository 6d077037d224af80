"""Scoring a folder of MOTChallenge result files."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.errors import DataFormatError
from unitrack_env.metrics.motchallenge import score_folder as score_results
from unitrack_env.metrics.report import COMBINED, ScoreReport

motmetrics = pytest.importorskip("motmetrics")
TUD_DATA = Path(motmetrics.__file__).parent / "data"
TUD_LENGTHS = {"TUD-Campus": 71, "TUD-Stadtmitte": 179}
DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data"
MOT17_TRAIN = DATA / "MOT17" / "train"


@pytest.fixture()
def folders(tmp_path: Path) -> tuple[Path, Path]:
    """gt_root with both TUD sequences and a results folder with their tracker files."""
    if not (TUD_DATA / "TUD-Campus" / "gt.txt").is_file():
        pytest.skip("motmetrics wheel without its TUD data")
    gt_root, results = tmp_path / "gt", tmp_path / "results"
    results.mkdir()
    for seq, length in TUD_LENGTHS.items():
        (gt_root / seq / "gt").mkdir(parents=True)
        shutil.copy(TUD_DATA / seq / "gt.txt", gt_root / seq / "gt" / "gt.txt")
        (gt_root / seq / "seqinfo.ini").write_text(f"[Sequence]\nname={seq}\nseqLength={length}\n")
        shutil.copy(TUD_DATA / seq / "test.txt", results / f"{seq}.txt")
    return gt_root, results


def test_scores_every_result_file(folders: tuple[Path, Path]) -> None:
    report = score_results(*folders, benchmark="MOT15")
    assert isinstance(report, ScoreReport) and report.benchmark == "MOT15"
    assert sorted(report.per_sequence) == sorted(TUD_LENGTHS)
    assert report.per_sequence["TUD-Campus"]["MOTA"] == pytest.approx(0.526462, abs=1e-6)
    assert report.per_sequence["TUD-Stadtmitte"]["IDF1"] == pytest.approx(0.644619, abs=1e-6)
    assert report.combined["IDSW"] == 14
    assert report.combined["MOTA"] == pytest.approx((189 + 652) / 1515)
    assert report.combined["IDF1"] == pytest.approx(2 * 776 / (1515 + 971))
    assert report.scores[COMBINED].summary == report.combined

    payload = json.loads(report.to_json())
    assert payload["benchmark"] == "MOT15"
    assert payload["combined"]["MOTA"] == report.combined["MOTA"]
    assert payload["per_sequence"]["TUD-Campus"]["IDSW"] == 7


def test_listed_sequences_only(folders: tuple[Path, Path]) -> None:
    report = score_results(*folders, benchmark="MOT15", sequences=["TUD-Campus"])
    assert list(report.per_sequence) == ["TUD-Campus"]
    assert report.combined == report.per_sequence["TUD-Campus"]


def test_missing_result_file_is_named(folders: tuple[Path, Path]) -> None:
    gt_root, results = folders
    (results / "TUD-Stadtmitte.txt").unlink()
    with pytest.raises(DataFormatError, match="result file for sequence 'TUD-Stadtmitte'"):
        score_results(gt_root, results, benchmark="MOT15", sequences=list(TUD_LENGTHS))


def test_result_without_ground_truth_is_named(folders: tuple[Path, Path]) -> None:
    gt_root, results = folders
    (results / "TUD-Crossing.txt").write_text("1,1,10,10,5,5,1,-1,-1,-1\n")
    with pytest.raises(DataFormatError, match="sequence 'TUD-Crossing' has no ground truth") as e:
        score_results(gt_root, results, benchmark="MOT15")
    assert e.value.path == results / "TUD-Crossing.txt"


def test_a_benchmark_folder_or_a_run_folder_says_where_to_point(
        folders: tuple[Path, Path]) -> None:
    gt_root, results = folders
    benchmark, run = gt_root.parent / "MOT15", results.parent / "run"
    benchmark.mkdir()
    run.mkdir()
    gt_root.rename(benchmark / "train")
    results.rename(run / "data")
    with pytest.raises(DataFormatError, match=f"the ground truth folder is the split folder "
                                              f"{benchmark / 'train'}$"):
        score_results(benchmark, run / "data", benchmark="MOT15")
    with pytest.raises(DataFormatError, match=f"the run's result files are in {run / 'data'}$"):
        score_results(benchmark / "train", run, benchmark="MOT15")


def test_malformed_line_names_file_line_and_field(folders: tuple[Path, Path]) -> None:
    gt_root, results = folders
    bad = results / "TUD-Campus.txt"
    lines = bad.read_text().splitlines()
    parts = lines[4].split(",")
    parts[4] = "wide"
    lines[4] = ",".join(parts)
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFormatError) as info:
        score_results(gt_root, results, benchmark="MOT15")
    assert (info.value.path, info.value.line, info.value.field) == (bad, 5, "bb_width")
    assert "TUD-Campus.txt, line 5, field 'bb_width': 'wide' is not a number" in str(info.value)


def test_empty_or_missing_folders(tmp_path: Path) -> None:
    (tmp_path / "gt").mkdir()
    (tmp_path / "res").mkdir()
    with pytest.raises(DataFormatError, match="contains no result files"):
        score_results(tmp_path / "gt", tmp_path / "res", benchmark="MOT17")
    with pytest.raises(DataFormatError, match="results folder not found"):
        score_results(tmp_path / "gt", tmp_path / "nope", benchmark="MOT17")
    (tmp_path / "res" / "S1.txt").write_text("")
    with pytest.raises(DataFormatError, match="is a file; --results takes the folder"):
        score_results(tmp_path / "gt", tmp_path / "res" / "S1.txt", benchmark="MOT17")
    with pytest.raises(DataFormatError, match="ground-truth folder not found"):
        score_results(tmp_path / "nope", tmp_path / "res", benchmark="MOT17")


def test_real_mot17_clips(tmp_path: Path) -> None:
    seqs = sorted(MOT17_TRAIN.glob("MOT17-*")) if MOT17_TRAIN.is_dir() else []
    if not seqs:
        pytest.skip(f"MOT17 fixtures not found under {MOT17_TRAIN}")
    results = tmp_path / "results"
    results.mkdir()
    total_gt = 0
    for seq in seqs:
        gt = np.loadtxt(seq / "gt" / "gt.txt", delimiter=",", ndmin=2)
        kept = gt[(gt[:, 7] == 1) & (gt[:, 6] != 0)]
        total_gt += len(kept)
        # a tracker that misses every other evaluated box
        np.savetxt(results / f"{seq.name}.txt", kept[::2, :6], fmt="%g", delimiter=",")
    report = score_results(MOT17_TRAIN, results, benchmark="MOT17")
    assert sorted(report.per_sequence) == [s.name for s in seqs]
    assert report.combined["GT_Dets"] == total_gt
    assert report.combined["CLR_FP"] == 0 and report.combined["IDSW"] == 0
    assert report.combined["MOTA"] == pytest.approx(report.combined["CLR_TP"] / total_gt)
    assert report.combined["CLR_TP"] == sum(
        len(np.loadtxt(results / f"{s.name}.txt", delimiter=",", ndmin=2)) for s in seqs
    )
