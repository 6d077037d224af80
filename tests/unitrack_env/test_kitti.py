"""Issue 40: UniTrack/KITTI-v0 plays KITTI tracking and scores it exactly as TrackEval does."""

from __future__ import annotations

import json
import os
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.errors import DataFormatError
from unitrack_env.evaluation.cli import main

ENV = "UniTrack/KITTI-v0"


def trackeval_direct(label_dir: Path, results: Path, lengths: dict[str, int], tmp: Path):
    """TrackEval's own Evaluator on the KITTI layout: its output and the class combinations."""
    import trackeval

    gt = tmp / "gt"
    (gt / "label_02").mkdir(parents=True)
    data = tmp / "trackers" / "mine" / "data"
    data.mkdir(parents=True)
    for seq in lengths:
        os.symlink(label_dir / f"{seq}.txt", gt / "label_02" / f"{seq}.txt")
        os.symlink(results / f"{seq}.txt", data / f"{seq}.txt")
    (gt / "evaluate_tracking.seqmap.training").write_text(
        "".join(f"{seq} empty 000000 {n:06d}\n" for seq, n in lengths.items()))
    config = {**trackeval.Evaluator.get_default_eval_config(), "USE_PARALLEL": False,
              "PRINT_RESULTS": False, "PRINT_CONFIG": False, "TIME_PROGRESS": False,
              "OUTPUT_SUMMARY": False, "OUTPUT_DETAILED": False, "PLOT_CURVES": False,
              "DISPLAY_LESS_PROGRESS": True}
    dataset = trackeval.datasets.Kitti2DBox({
        "GT_FOLDER": str(gt), "TRACKERS_FOLDER": str(tmp / "trackers"),
        "OUTPUT_FOLDER": str(tmp / "out"), "PRINT_CONFIG": False})
    metrics = [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR({"PRINT_CONFIG": False}),
               trackeval.metrics.Identity({"PRINT_CONFIG": False})]
    results_, _ = trackeval.Evaluator(config).evaluate([dataset], metrics)
    res = results_["Kitti2DBox"]["mine"]
    combined = res["COMBINED_SEQ"]
    for key, how in (("cls_comb_cls_av", "combine_classes_class_averaged"),
                     ("cls_comb_det_av", "combine_classes_det_averaged")):
        combined[key] = {m.get_name(): getattr(m, how)(
            {c: combined[c][m.get_name()] for c in ("car", "pedestrian")}) for m in metrics}
    return res


def assert_parity(ours: dict[str, float], theirs: dict) -> None:
    checked = 0
    for key, value in ours.items():
        group, _, name = key.rpartition("/")
        if not group:
            continue
        for metric in ("HOTA", "CLEAR", "Identity"):
            if name in theirs[group][metric]:
                expected = theirs[group][metric][name]
                expected = float(np.mean(expected)) if np.ndim(expected) else float(expected)
                assert value == expected, (key, value, expected)  # every digit
                checked += 1
    assert checked >= 20


def _noisy_detections(label: Path, out: Path) -> Path:
    """Detections from the ground truth (DontCare dropped), boxes shifted by up to 1.5 px."""
    out.mkdir()
    rows = []
    for k, line in enumerate(label.read_text().splitlines()):
        cells = line.split()
        if cells[2] == "DontCare":
            continue
        cells[1] = "-1"
        cells[6:10] = [f"{float(v) + ((k % 3) - 1) * 1.5:.2f}" for v in cells[6:10]]
        rows.append(" ".join(cells) + " 0.9\n")
    (out / label.name).write_text("".join(rows))
    return out


def test_check_env_on_the_synthetic_default():
    env = gym.make(ENV)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


@pytest.mark.parametrize("agent", ["iou", "unitrack"])
def test_real_frames_score_as_trackeval_per_class(agent, shared_data, tmp_path):
    root = shared_data / "KITTI" / "tracking"
    dets = _noisy_detections(root / "training" / "label_02" / "0001.txt", tmp_path / "dets")
    out = tmp_path / "run"
    assert main(["evaluate", "--env", ENV, "--root", str(root), "--env-arg",
                 f"detections={dets}", "--agent", agent, "--out", str(out), "--quiet"]) == 0
    ours = json.loads((out / "metrics.json").read_text())
    theirs = trackeval_direct(root / "training" / "label_02", out / "data", {"0001": 2},
                              tmp_path / "te")
    assert_parity(ours["combined"], theirs["COMBINED_SEQ"])
    assert_parity(ours["per_sequence"]["0001"], theirs["0001"] | {
        k: v for k, v in theirs["COMBINED_SEQ"].items() if k.startswith("cls_comb")})
    assert ours["combined"]["car/MOTA"] > 0.8  # the detections are the ground truth, shifted


def test_synthetic_default_plays_and_scores_as_trackeval(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["evaluate", "--env", ENV, "--agent", "iou", "--out", str(out),
                 "--quiet"]) == 0
    ours = json.loads((out / "metrics.json").read_text())
    env = gym.make(ENV)
    split = env.unwrapped.dataset.split_dir
    env.close()
    theirs = trackeval_direct(split / "label_02", out / "data", {"0000": 16, "0001": 16},
                              tmp_path / "te")
    assert_parity(ours["combined"], theirs["COMBINED_SEQ"])
    for seq in ("0000", "0001"):  # per sequence and class
        assert ours["per_sequence"][seq]["car/HOTA"] == float(np.mean(
            theirs[seq]["car"]["HOTA"]["HOTA"]))
        assert ours["per_sequence"][seq]["pedestrian/IDF1"] == float(
            theirs[seq]["pedestrian"]["Identity"]["IDF1"])
    assert 0 < ours["combined"]["pedestrian/HOTA"] < 1  # both classes present and scored
    capsys.readouterr()
    assert main(["score", "--env", ENV, "--results", str(out / "data"),
                 "--format", "json"]) == 0
    scored = json.loads(capsys.readouterr().out)
    assert scored["combined"]["car/HOTA"] == ours["combined"]["car/HOTA"]


def test_real_data_without_detections_is_refused_with_the_expected_path(shared_data):
    root = shared_data / "KITTI" / "tracking"
    with pytest.raises(DataFormatError, match="det_02/0001.txt.*no detections"):
        gym.make(ENV, root=str(root))


def test_a_bad_result_line_is_named(tmp_path):
    env = gym.make(ENV)
    bench = env.unwrapped.scoring
    env.close()
    (tmp_path / "0000.txt").write_text("0 1 Car -1 -1 -10 1 2 x 4\n")
    (tmp_path / "0001.txt").write_text("")
    with pytest.raises(DataFormatError, match="line 1, field 'x2'"):
        bench.score_folder(tmp_path)
