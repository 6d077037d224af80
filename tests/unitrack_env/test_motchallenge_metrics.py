"""TrackEval adapter: parity with published numbers, TrackEval's Evaluator, and clean errors."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.errors import DataFormatError
from unitrack_env.metrics.mot_results import read_result_file
from unitrack_env.metrics.motchallenge import (
    SequenceScore,
    combine_sequence_scores,
    combine_sequences,
    score_sequence,
)

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / ".." / "shared" / "data"
MOT17_02 = DATA / "MOT17" / "train" / "MOT17-02-FRCNN"

motmetrics = pytest.importorskip("motmetrics")
TUD_DATA = Path(motmetrics.__file__).parent / "data"
TUD_LENGTHS = {"TUD-Campus": 71, "TUD-Stadtmitte": 179}
# Published by py-motmetrics and TrackEval for these files (BENCHMARK='MOT15').
TUD_EXPECTED = {
    "TUD-Campus": {"MOTA": 0.526462, "IDF1": 0.557659, "IDSW": 7},
    "TUD-Stadtmitte": {"MOTA": 0.564014, "IDF1": 0.644619, "IDSW": 7},
}


def make_layout(root: Path, seq: str, *, with_ini: bool = True) -> Path:
    """A MOTChallenge sequence folder built from the files shipped inside motmetrics."""
    seq_dir = root / seq
    (seq_dir / "gt").mkdir(parents=True)
    shutil.copy(TUD_DATA / seq / "gt.txt", seq_dir / "gt" / "gt.txt")
    if with_ini:
        (seq_dir / "seqinfo.ini").write_text(
            f"[Sequence]\nname={seq}\nimDir=img1\nframeRate=25\nseqLength={TUD_LENGTHS[seq]}\n"
            "imWidth=640\nimHeight=480\nimExt=.jpg\n"
        )
    return seq_dir


@pytest.fixture()
def tud(tmp_path: Path) -> dict[str, Path]:
    if not (TUD_DATA / "TUD-Campus" / "gt.txt").is_file():
        pytest.skip("motmetrics wheel without its TUD data")
    return {seq: make_layout(tmp_path / "gt", seq) for seq in TUD_LENGTHS}


@pytest.mark.parametrize("seq", sorted(TUD_EXPECTED))
def test_tud_parity_with_published_numbers(tud: dict[str, Path], seq: str) -> None:
    score = score_sequence(tud[seq], TUD_DATA / seq / "test.txt", benchmark="MOT15")
    expected = TUD_EXPECTED[seq]
    assert score["MOTA"] == pytest.approx(expected["MOTA"], abs=1e-6)
    assert score["IDF1"] == pytest.approx(expected["IDF1"], abs=1e-6)
    assert score["IDSW"] == expected["IDSW"]
    assert isinstance(score, SequenceScore) and score.sequence == seq
    for key in (
        "HOTA",
        "DetA",
        "AssA",
        "LocA",
        "MOTA",
        "MOTP",
        "IDF1",
        "IDP",
        "IDR",
        "IDSW",
        "CLR_TP",
        "CLR_FP",
        "CLR_FN",
        "MT",
        "PT",
        "ML",
        "Frag",
        "GT_Dets",
        "GT_IDs",
        "Dets",
        "IDs",
        "IDTP",
        "IDFP",
        "IDFN",
    ):
        assert isinstance(score[key], float), key
    for key in ("HOTA", "DetA", "AssA", "LocA", "MOTP", "IDF1"):
        assert 0.0 < score[key] < 1.0, key  # fractions, not percent
    # the HOTA family is the mean over TrackEval's 19 alpha thresholds
    assert score.raw["HOTA"]["HOTA"].shape == (19,)
    assert score["HOTA"] == pytest.approx(float(np.mean(score.raw["HOTA"]["HOTA"])))


def test_array_and_file_inputs_agree(tud: dict[str, Path]) -> None:
    path = TUD_DATA / "TUD-Campus" / "test.txt"
    rows = read_result_file(path)
    assert rows.shape[1] == 10
    by_file = score_sequence(tud["TUD-Campus"], path, benchmark="MOT15")
    by_rows = score_sequence(tud["TUD-Campus"], rows, benchmark="MOT15")
    by_six = score_sequence(tud["TUD-Campus"], rows[:, :6], benchmark="MOT15")
    assert dict(by_file) == dict(by_rows) == dict(by_six)


def test_ids_are_relabelled_safely(tud: dict[str, Path]) -> None:
    rows = read_result_file(TUD_DATA / "TUD-Campus" / "test.txt")
    huge = rows.copy()
    huge[:, 1] = huge[:, 1] * 10**12 - 7  # TrackEval alone would allocate by the raw id
    base = score_sequence(tud["TUD-Campus"], rows, benchmark="MOT15")
    assert dict(score_sequence(tud["TUD-Campus"], huge, benchmark="MOT15")) == dict(base)


def test_missing_seqinfo_needs_seq_length(tmp_path: Path) -> None:
    if not (TUD_DATA / "TUD-Campus" / "gt.txt").is_file():
        pytest.skip("motmetrics wheel without its TUD data")
    seq_dir = make_layout(tmp_path, "TUD-Campus", with_ini=False)
    rows = read_result_file(TUD_DATA / "TUD-Campus" / "test.txt")
    score = score_sequence(seq_dir, rows, benchmark="MOT15", seq_length=71)
    assert score["MOTA"] == pytest.approx(0.526462, abs=1e-6)
    with pytest.raises(DataFormatError, match=r"seqinfo.ini: missing; pass seq_length="):
        score_sequence(seq_dir, rows, benchmark="MOT15")


def test_combine_matches_trackeval_evaluator(tud: dict[str, Path], tmp_path: Path) -> None:
    scores = {
        seq: score_sequence(path, TUD_DATA / seq / "test.txt", benchmark="MOT15")
        for seq, path in tud.items()
    }
    combined = combine_sequences(scores)
    # known answer from the summed counts
    assert combined["MOTA"] == pytest.approx((209 - 13 - 7 + 704 - 45 - 7) / (359 + 1156))
    assert combined["IDSW"] == 14 and combined["GT_Dets"] == 1515

    # and TrackEval's own Evaluator over the same two sequences
    import trackeval

    trackers = tmp_path / "trackers" / "ref" / "data"
    trackers.mkdir(parents=True)
    for seq in tud:
        shutil.copy(TUD_DATA / seq / "test.txt", trackers / f"{seq}.txt")
    eval_config = {
        "USE_PARALLEL": False,
        "PRINT_RESULTS": False,
        "PRINT_CONFIG": False,
        "TIME_PROGRESS": False,
        "OUTPUT_SUMMARY": False,
        "OUTPUT_EMPTY_CLASSES": False,
        "OUTPUT_DETAILED": False,
        "PLOT_CURVES": False,
        "LOG_ON_ERROR": str(tmp_path / "log"),
        "BREAK_ON_ERROR": True,
        "DISPLAY_LESS_PROGRESS": True,
    }
    dataset_config = {
        "GT_FOLDER": str(tmp_path / "gt"),
        "TRACKERS_FOLDER": str(tmp_path / "trackers"),
        "OUTPUT_FOLDER": str(tmp_path / "out"),
        "BENCHMARK": "MOT15",
        "SKIP_SPLIT_FOL": True,
        "SEQ_INFO": dict.fromkeys(tud),
        "TRACKERS_TO_EVAL": ["ref"],
        "PRINT_CONFIG": False,
    }
    metrics = [
        trackeval.metrics.HOTA(),
        trackeval.metrics.CLEAR({"PRINT_CONFIG": False}),
        trackeval.metrics.Identity({"PRINT_CONFIG": False}),
    ]
    results, _ = trackeval.Evaluator(eval_config).evaluate(
        [trackeval.datasets.MotChallenge2DBox(dataset_config)], metrics
    )
    ref = results["MotChallenge2DBox"]["ref"]["COMBINED_SEQ"]["pedestrian"]
    for metric, key in (
        ("HOTA", "HOTA"),
        ("HOTA", "DetA"),
        ("HOTA", "AssA"),
        ("HOTA", "LocA"),
        ("CLEAR", "MOTA"),
        ("CLEAR", "MOTP"),
        ("CLEAR", "Frag"),
        ("Identity", "IDF1"),
    ):
        assert combined[key] == pytest.approx(float(np.mean(ref[metric][key])), abs=1e-12), key
    assert combine_sequence_scores(scores).sequence == "COMBINED"
    with pytest.raises(ValueError, match="no sequence scores"):
        combine_sequences({})


def test_scoring_prints_nothing(tud: dict[str, Path]) -> None:
    # A fresh interpreter, so that TrackEval's import-time messages would be seen too.
    code = (
        "import json, sys\n"
        "from unitrack_env.metrics.motchallenge import score_sequence\n"
        f"s = score_sequence({str(tud['TUD-Campus'])!r}, "
        f"{str(TUD_DATA / 'TUD-Campus' / 'test.txt')!r}, benchmark='MOT15')\n"
        "sys.stderr.write(json.dumps(s['MOTA']))\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={"PYTHONPATH": str(REPO), "PATH": ""},
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == ""
    assert json.loads(proc.stderr.strip().splitlines()[-1]) == pytest.approx(0.526462, abs=1e-6)


def test_perfect_tracker_on_a_real_mot17_clip() -> None:
    if not (MOT17_02 / "gt" / "gt.txt").is_file():
        pytest.skip(f"MOT17 fixture not found at {MOT17_02}")
    gt = np.loadtxt(MOT17_02 / "gt" / "gt.txt", delimiter=",", ndmin=2)
    evaluated = gt[(gt[:, 7] == 1) & (gt[:, 6] != 0)]
    score = score_sequence(MOT17_02, evaluated[:, :6], benchmark="MOT17")
    for key in ("MOTA", "IDF1", "HOTA", "DetA", "AssA", "LocA", "MOTP"):
        assert score[key] == pytest.approx(1.0), key
    assert score["GT_Dets"] == len(evaluated) and score["CLR_FP"] == 0
    # boxes on every gt row: distractor classes vanish, vehicles/occluders become FPs
    everything = score_sequence(MOT17_02, gt[:, :6], benchmark="MOT17")
    distractors = np.isin(gt[:, 7], [2, 7, 8, 12])
    assert everything["CLR_TP"] == len(evaluated)
    assert everything["CLR_FP"] == len(gt) - len(evaluated) - distractors.sum()


def test_mot20_also_removes_non_mot_vehicles(tmp_path: Path) -> None:
    seq_dir = tmp_path / "SEQ-01"
    (seq_dir / "gt").mkdir(parents=True)
    (seq_dir / "gt" / "gt.txt").write_text(
        "1,1,10,10,50,100,1,1,1.0\n1,2,200,10,80,60,1,6,1.0\n2,1,12,10,50,100,1,1,1.0\n"
    )
    rows = np.array([[1, 5, 10, 10, 50, 100], [1, 6, 200, 10, 80, 60], [2, 5, 12, 10, 50, 100]])
    counts = {
        b: (s["CLR_TP"], s["CLR_FP"])
        for b in ("MOT16", "MOT17", "MOT20")
        for s in [score_sequence(seq_dir, rows, benchmark=b, seq_length=2)]
    }
    assert counts == {"MOT16": (2, 1), "MOT17": (2, 1), "MOT20": (2, 0)}


def test_empty_tracker(tud: dict[str, Path]) -> None:
    score = score_sequence(tud["TUD-Campus"], np.zeros((0, 6)), benchmark="MOT15")
    assert score["MOTA"] == 0.0 and score["HOTA"] == 0.0
    assert score["CLR_FN"] == score["GT_Dets"] == 359


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "text,line,field,message",
    [
        ("1,1,10,10,5,5,1\n1,2,10,abc,5,5,1\n", 2, "bb_top", "'abc' is not a number"),
        ("1,1,10,10,5\n", 1, None, "at least 6"),
        ("1,1,10,10,5,5\n\n2,1,10,10,5,5,1\n", 3, None, "7 fields but earlier lines have 6"),
        ("0,1,10,10,5,5\n", 1, "frame", "1-based"),
        ("1.5,1,10,10,5,5\n", 1, "frame", "integer"),
        ("1,2.5,10,10,5,5\n", 1, "id", "integer"),
        ("1,1,nan,10,5,5\n", 1, "bb_left", "finite"),
        ("1,1,10,10,5,5\n72,1,10,10,5,5\n", 2, "frame", r"frame 72 is outside the sequence"),
        ("1,1,10,10,5,5\n2,1,1,1,5,5\n2,1,10,10,5,5\n", 3, "id", "id 1 appears more than once"),
        ("1,1,10,10,5,5,1,3,-1,-1\n", 1, "x", "class id"),
    ],
)
def test_malformed_result_files(
    tud: dict[str, Path], tmp_path: Path, text: str, line: int, field: str | None, message: str
) -> None:
    path = write(tmp_path / "res.txt", text)
    with pytest.raises(DataFormatError, match=message) as info:
        score_sequence(tud["TUD-Campus"], path, benchmark="MOT15")
    assert info.value.path == path and info.value.line == line and info.value.field == field


def test_malformed_arrays_and_missing_files(tud: dict[str, Path], tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"row 1: column 'frame': frame 80 is outside"):
        score_sequence(
            tud["TUD-Campus"],
            np.array([[1, 1, 0, 0, 5, 5], [80, 1, 0, 0, 5, 5]]),
            benchmark="MOT15",
        )
    with pytest.raises(ValueError, match=r"expected a \(k, >=6\) array"):
        score_sequence(tud["TUD-Campus"], np.ones((3, 4)), benchmark="MOT15")
    with pytest.raises(DataFormatError, match="ground truth not found"):
        score_sequence(tmp_path / "nope", np.zeros((0, 6)), benchmark="MOT15", seq_length=3)
    with pytest.raises(DataFormatError, match="result file not found"):
        score_sequence(tud["TUD-Campus"], tmp_path / "missing.txt", benchmark="MOT15")
    with pytest.raises(ValueError, match="unknown MOTChallenge benchmark"):
        score_sequence(tud["TUD-Campus"], np.zeros((0, 6)), benchmark="KITTI")


def test_trackeval_rejections_become_data_format_errors(tmp_path: Path) -> None:
    seq_dir = tmp_path / "SEQ-01"
    (seq_dir / "gt").mkdir(parents=True)
    # MOT15-style gt (no class column) scored as MOT17: TrackEval refuses the class -4
    (seq_dir / "gt" / "gt.txt").write_text("1,1,10,10,50,100,1,-4.2,-7.3,0\n")
    rows = np.array([[1, 1, 10, 10, 50, 100]])
    with pytest.raises(ValueError, match="benchmark='MOT15'"):
        from unitrack_env.metrics.clear_stream import clear_from_frames
        from unitrack_env.metrics.mot_preprocess import (
            gt_frames_from_rows,
            tracker_frames_from_rows,
        )

        gt = np.loadtxt(seq_dir / "gt" / "gt.txt", delimiter=",", ndmin=2)
        clear_from_frames(
            gt_frames_from_rows(gt, 1, benchmark="MOT17"),
            tracker_frames_from_rows(rows, 1),
            benchmark="MOT17",
        )
    with pytest.raises(DataFormatError, match=r"gt\.txt: TrackEval rejected the data"):
        score_sequence(seq_dir, rows, benchmark="MOT17", seq_length=1)
    assert score_sequence(seq_dir, rows, benchmark="MOT15", seq_length=1)["MOTA"] == 1.0
