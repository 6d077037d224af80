"""Issue 40: UniTrack/BDD100K-v0 plays BDD100K box tracking and scores it as TrackEval does."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.errors import DataFormatError
from unitrack_env.evaluation.cli import main

ENV = "UniTrack/BDD100K-v0"
REAL_SEQ = "track_sample_anns"
#: The groups TrackEval reports for BDD100K besides the 8 classes (its "all" left aside).
GROUPS = ("cls_comb_cls_av", "cls_comb_det_av", "HUMAN", "VEHICLE", "BIKE")


def _trackeval_flavour(path: Path, out: Path) -> None:
    """A Scalabel file in the JSON TrackEval's BDD100K class reads (index, int ids, Crowd)."""
    ids: dict[str, int] = {}
    frames = [{"index": frame["frameIndex"], "labels": [
        {"id": ids.setdefault(str(lab["id"]), len(ids)), "category": lab["category"],
         "box2d": lab["box2d"], "score": lab.get("score", 1.0),
         "attributes": {"Crowd": (lab.get("attributes") or {}).get("crowd", False)}}
        for lab in frame["labels"]]}
        for frame in sorted(json.loads(path.read_text()), key=lambda f: f["frameIndex"])]
    out.write_text(json.dumps(frames))


def trackeval_direct(labels: Path, results: Path, sequences: list[str], tmp: Path) -> dict:
    """TrackEval's own Evaluator and BDD100K dataset on the same files: {sequence: {group: ...}}."""
    import trackeval

    gt, data = tmp / "gt", tmp / "trackers" / "mine" / "data"
    gt.mkdir(parents=True)
    data.mkdir(parents=True)
    for seq in sequences:
        _trackeval_flavour(labels / f"{seq}.json", gt / f"{seq}.json")
        _trackeval_flavour(results / f"{seq}.json", data / f"{seq}.json")
    config = {**trackeval.Evaluator.get_default_eval_config(), "USE_PARALLEL": False,
              "PRINT_RESULTS": False, "PRINT_CONFIG": False, "TIME_PROGRESS": False,
              "OUTPUT_SUMMARY": False, "OUTPUT_DETAILED": False, "PLOT_CURVES": False,
              "DISPLAY_LESS_PROGRESS": True}
    dataset = trackeval.datasets.BDD100K({
        "GT_FOLDER": str(gt), "TRACKERS_FOLDER": str(tmp / "trackers"),
        "OUTPUT_FOLDER": str(tmp / "out"), "PRINT_CONFIG": False})
    metrics = [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR({"PRINT_CONFIG": False}),
               trackeval.metrics.Identity({"PRINT_CONFIG": False})]
    results_, _ = trackeval.Evaluator(config).evaluate([dataset], metrics)
    return results_["BDD100K"]["mine"]


def _theirs(group: dict, name: str) -> float | None:
    for metric in ("HOTA", "CLEAR", "Identity"):
        if name in group[metric]:
            value = group[metric][name]
            return float(np.mean(value)) if np.ndim(value) else float(value)
    return None


def assert_parity(ours: dict[str, float], theirs: dict) -> int:
    """Every ``<group>/<metric>`` of ours equals TrackEval's (every digit); the count checked."""
    checked = 0
    for key, value in ours.items():
        group, _, name = key.rpartition("/")
        if group in theirs and (expected := _theirs(theirs[group], name)) is not None:
            assert value == expected, (key, value, expected)
            checked += 1
    for name in ("HOTA", "MOTA", "IDF1", "IDSW"):  # unprefixed: the detection average
        assert ours[name] == _theirs(theirs["cls_comb_det_av"], name), name
    return checked


def _perturbed(gt_file: Path, out: Path) -> None:
    """Every 5th box dropped, boxes shifted by up to 3 px, ids of two cars swapped at 120."""
    frames = json.loads(gt_file.read_text())
    first, second = [lab["id"] for lab in frames[120]["labels"] if lab["category"] == "car"][:2]
    swap = {first: second, second: first}
    k = 0
    for frame in frames:
        kept = []
        for lab in frame["labels"]:
            k += 1
            if k % 5 == 0:
                continue
            shift = (k % 3 - 1) * 1.5 * (1 + k % 2)
            box = {key: value + shift for key, value in lab["box2d"].items()}
            kept.append({"id": swap.get(lab["id"], lab["id"]) if frame["frameIndex"] >= 120
                         else lab["id"], "category": lab["category"], "box2d": box,
                         "score": 0.3 + (k % 7) / 10})
        frame["labels"] = [lab for lab in kept if lab["category"] not in
                           ("other person", "trailer", "other vehicle")]
    out.write_text(json.dumps(frames))


def test_check_env_on_the_synthetic_default():
    env = gym.make(ENV)
    assert env.unwrapped.synthetic
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_iou_plays_the_synthetic_default_and_scores_as_trackeval(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["evaluate", "--env", ENV, "--agent", "iou", "--out", str(out), "--quiet"]) == 0
    ours = json.loads((out / "metrics.json").read_text())
    env = gym.make(ENV)
    labels, names = env.unwrapped.dataset.split_dir, list(env.unwrapped.sequence_names)
    env.close()
    written = json.loads((out / "data" / f"{names[0]}.json").read_text())
    assert written[0]["name"] == f"{names[0]}-0000001.jpg" and written[0]["frameIndex"] == 0
    assert {lab["category"] for f in written for lab in f["labels"]} >= {"car", "pedestrian"}
    theirs = trackeval_direct(labels, out / "data", names, tmp_path / "te")
    assert assert_parity(ours["combined"], theirs["COMBINED_SEQ"]) > 60
    for seq in names:  # per sequence, per class
        assert ours["per_sequence"][seq]["pedestrian/HOTA"] == _theirs(
            theirs[seq]["pedestrian"], "HOTA")
    combined = ours["combined"]
    assert 0.3 < combined["car/HOTA"] < 1 and 0.3 < combined["pedestrian/HOTA"] < 1
    assert 0.3 < combined["truck/HOTA"] < 1 and combined["HOTA"] > combined["cls_comb_cls_av/HOTA"]
    capsys.readouterr()
    assert main(["score", "--env", ENV, "--results", str(out / "data"), "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out)["combined"]["VEHICLE/HOTA"] == \
        combined["VEHICLE/HOTA"]


def test_the_synthetic_crowd_and_distractor_are_ignore_regions(tmp_path):
    env = gym.make(ENV)
    bench, labels = env.unwrapped.scoring, env.unwrapped.dataset.split_dir
    env.close()
    names = bench.sequence_names
    for seq in names:  # the ground truth given back without its ignore regions: all found
        frames = json.loads((labels / f"{seq}.json").read_text())
        ignored = sum(lab["attributes"]["crowd"] or lab["category"] == "other person"
                      for f in frames for lab in f["labels"])
        assert ignored > 0
        for frame in frames:
            frame["labels"] = [lab for lab in frame["labels"] if not lab["attributes"]["crowd"]
                               and lab["category"] != "other person"]
        (tmp_path / f"{seq}.json").write_text(json.dumps(frames))
    combined = bench.score_folder(tmp_path).combined
    assert combined["HOTA"] == 1.0 and combined["MOTA"] == 1.0


def _score_cli(capsys, root: Path, results: Path, fmt: str) -> str:
    capsys.readouterr()
    assert main(["score", "--env", ENV, "--root", str(root), "--results", str(results),
                 "--format", fmt]) == 0
    return capsys.readouterr().out


def test_real_ground_truth_given_back_scores_hota_100(shared_data, tmp_path, capsys):
    root = shared_data / "BDD100K"
    gt = root / "labels" / "box_track_20" / "val" / f"{REAL_SEQ}.json"
    (tmp_path / "res").mkdir()
    shutil.copy(gt, tmp_path / "res" / gt.name)
    combined = json.loads(_score_cli(capsys, root, tmp_path / "res", "json"))["combined"]
    assert combined["HOTA"] == 1.0 and combined["cls_comb_det_av/HOTA"] == 1.0
    assert combined["cls_comb_cls_av/HOTA"] == 0.75  # train and bicycle absent: 0 (the page)
    assert all(combined[f"{c}/HOTA"] == 1.0 for c in ("car", "pedestrian", "rider", "bus",
                                                     "truck", "motorcycle", "HUMAN", "BIKE"))
    csv = _score_cli(capsys, root, tmp_path / "res", "csv").splitlines()
    header, row = csv[0].split(","), next(r for r in csv if r.startswith("COMBINED")).split(",")
    assert float(row[header.index("HOTA")]) in (1.0, 100.0)


def test_real_perturbed_results_give_trackeval_numbers_from_the_cli(shared_data, tmp_path,
                                                                   capsys):
    root = shared_data / "BDD100K"
    labels = root / "labels" / "box_track_20" / "val"
    (tmp_path / "res").mkdir()
    _perturbed(labels / f"{REAL_SEQ}.json", tmp_path / "res" / f"{REAL_SEQ}.json")
    printed = json.loads(_score_cli(capsys, root, tmp_path / "res", "json"))
    theirs = trackeval_direct(labels, tmp_path / "res", [REAL_SEQ], tmp_path / "te")
    checked = assert_parity(printed["combined"], theirs["COMBINED_SEQ"])
    assert checked == 6 * 13  # 6 metrics of 8 classes, 3 super-categories, 2 combinations
    assert 0.5 < printed["combined"]["HOTA"] < 0.95 and printed["combined"]["IDSW"] >= 2
    table = _score_cli(capsys, root, tmp_path / "res", "table")
    hota = _theirs(theirs["COMBINED_SEQ"]["cls_comb_det_av"], "HOTA")
    assert f"{100 * hota:.1f}" in table.split("COMBINED")[1].splitlines()[0]


def test_evaluate_on_labels_without_frames_names_the_image_folder(shared_data, tmp_path,
                                                                  capsys):
    root = shared_data / "BDD100K"
    with pytest.raises(DataFormatError, match=r"images/track/val/b1c66a42-6f7d68ca: missing"):
        gym.make(ENV, root=str(root))
    assert main(["evaluate", "--env", ENV, "--root", str(root), "--agent", "iou", "--out",
                 str(tmp_path / "run"), "--quiet"]) != 0
    assert "images/track/val/b1c66a42-6f7d68ca: missing" in capsys.readouterr().err


def _synthetic_copy(tmp_path: Path) -> Path:
    env = gym.make(ENV)
    source = env.unwrapped.dataset.root
    env.close()
    return Path(shutil.copytree(source, tmp_path / "BDD100K"))


def test_data_without_detections_is_refused_with_the_expected_path(tmp_path):
    root = _synthetic_copy(tmp_path)
    shutil.rmtree(root / "detections")
    with pytest.raises(DataFormatError, match=r"detections/box_track_20/val/"
                       r"5y7e71c0-00000001.json: no detections: BDD100K ships none"):
        gym.make(ENV, root=str(root))
    env = gym.make(ENV, root=str(root), detections=str(_synthetic_copy(tmp_path / "b")
                                                      / "detections" / "box_track_20" / "val"))
    env.close()
